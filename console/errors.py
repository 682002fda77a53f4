"""The console's error contract: every failure is one line on stderr (a JSON object under
`--json`), exit 2 for bad input, 1 for a refused or failed command, never a traceback.

Light on purpose: `stop` imports this before it sends anything (no config or pydantic here).
"""
from __future__ import annotations

import functools
import json
import sys

TYPE_CHECKING = False   # typing itself is ~10 ms of a stop's start-up: annotations only
if TYPE_CHECKING:
    from typing import Callable, TypeVar

    F = TypeVar("F", bound=Callable)

EXIT_USAGE = 2
EXIT_FAILED = 1


class CommandFailed(Exception):
    """A command could not do what was asked; the message is shown to the operator, the code
    (the daemon's ErrorCode value, or a console code) is what code branches on."""

    exit_code = EXIT_FAILED

    def __init__(self, message: str, code: str | None = None):
        super().__init__(message)
        self.code = code


class BadInput(CommandFailed):
    """The operator typed something the console cannot use (a value, a unit, a file): exit 2."""

    exit_code = EXIT_USAGE

    def __init__(self, message: str, code: str | None = "bad_input"):
        super().__init__(message, code)


def report(message: str, code: str | None, exit_code: int, as_json: bool) -> SystemExit:
    """Print the one line and return the SystemExit to raise (`raise report(...)`)."""
    message = " ".join(str(message).split())          # one line, whatever the source said
    code = str(code) if code is not None else None
    if as_json:
        print(json.dumps({"ok": False, "error": message, "code": code, "exit": exit_code}), file=sys.stderr)
    else:
        print(f"error[{code}]: {message}" if code else f"error: {message}", file=sys.stderr)
    return SystemExit(exit_code)


# The daemon's answers that mean "what you typed is wrong" (exit 2 like the console's own checks).
BAD_INPUT_CODES = {"bad_argument", "bad_request", "bad_input", "bad_usage", "bad_config", "bad_bus"}

# Exceptions of the layers below that mean bad input, by class name (importing them would
# make every command pay for the whole stack): a configuration, recording, bus spec or unit
# the operator named.
BAD_INPUT_TYPES = {"ConfigError": "bad_config", "RecordingError": "bad_recording",
                   "RecordingFormatError": "bad_recording", "BusSpecError": "bad_bus", "UnitError": "bad_input"}


def classify(exc: BaseException) -> tuple[str, str, int] | None:
    """(message, code, exit code) for an exception the contract knows, else None (a bug)."""
    if isinstance(exc, CommandFailed):
        code = str(exc.code) if exc.code is not None else None
        return str(exc), code, EXIT_USAGE if code in BAD_INPUT_CODES else exc.exit_code
    for cls in type(exc).__mro__:
        if cls.__name__ in BAD_INPUT_TYPES:
            return str(exc), BAD_INPUT_TYPES[cls.__name__], EXIT_USAGE
    if isinstance(exc, (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError)):
        return f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": "), "bad_file", EXIT_USAGE
    return None


def friendly_errors(func: F) -> F:
    """Apply the contract to one command (its `as_json` keyword, when it has one, picks JSON)."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        as_json = bool(kwargs.get("as_json", False))
        try:
            return func(*args, **kwargs)
        except Exception as exc:
            known = classify(exc)
            if known is None:
                raise
            raise report(*known, as_json) from None
    return wrapper  # type: ignore[return-value]
