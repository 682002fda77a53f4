"""spacearm: a hardware-in-the-loop controller stack for a space manipulator over CANopen."""
from pathlib import Path as _Path

# In a clone, the rooms (spacearm.base, spacearm.controller, ...) are top-level folders beside
# this package (setup.py). Looking for them beside the `spacearm` that was imported, before the
# editable install's fixed mapping, makes a second clone or worktree run its own rooms when it
# is first on sys.path, not those of the clone that was installed.
_clone = _Path(__file__).resolve().parent.parent
if all((_clone / room / "__init__.py").is_file() for room in ("base", "controller", "drivers")):
    __path__.append(str(_clone))
