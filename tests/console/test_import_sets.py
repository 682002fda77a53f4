"""What each console command imports (module names, not time): a command that talks to the
daemon imports the API client and the command line's own parsing, never the controller stack,
the planner or scipy; `--help` and `kin` never scipy.stats. Each command runs as the operator
types it (a new interpreter), against an API address where nothing listens."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
import typer

from spacearm.console.command_index import COMMANDS
from spacearm.console.main import build_app

ARM = "configs/arm/oru_testbed_6dof.toml"

# The spacearm modules a daemon-talking command may import: the client and the console's own.
CLIENT_MODULES = {"spacearm", "spacearm.console", "spacearm.console.main", "spacearm.console.command_index",
                  "spacearm.console.client", "spacearm.console.errors", "spacearm.console.quick",
                  "spacearm.console.control", "spacearm.console.lease_store", "spacearm.console.units",
                  "spacearm.console.status_view", "spacearm.console.daemon_calls", "spacearm.console.commands", "spacearm.console.commands.operate",
                  "spacearm.console.commands.oru", "spacearm.controller", "spacearm.controller.daemon",
                  "spacearm.controller.daemon.api_errors"}
# Standard modules the fast path does without: typing (annotations only), the idna codec (a str
# host given to the resolver loads it), getpass (only when a lease is taken).
SLOW_STDLIB = {"typing", "encodings.idna", "getpass"}
HEAVY = ("numpy", "scipy", "pydantic", "can", "aiohttp", "cv2", "pandas", "dask")

# Parsed without typer (console/quick.py): nothing heavy at all.
PLAIN = [["oru", "pause"], ["oru", "resume"], ["oru", "abort"], ["oru", "status"], ["control", "take"],
         ["control", "release"], ["record", "start"], ["record", "stop"], ["watch", "--count", "1"],
         ["status"], ["stop"], ["enable"]]
# With arguments in units and motion options, parsed by typer, whose parameter coercion
# imports pydantic (typer 0.29): still nothing of the stack.
TYPED = [["oru", "run"], ["jog", "1", "1deg"], ["move", "joints", "ready"], ["move", "pose", "0", "0", "1mm", "0", "0", "0"]]


@pytest.fixture(scope="module")
def closed_api() -> str:
    """A loopback API address where nothing listens (the command fails at once, in one line)."""
    import socket
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"tcp:127.0.0.1:{sock.getsockname()[1]}"


def imported(args: list[str]) -> set[str]:
    """sys.modules after `spacearm ARGS` ran to its end (here: its one-line error or help)."""
    code = ("import json, sys\nfrom spacearm.console.main import main\n"
            f"try:\n    main({args!r})\nexcept SystemExit:\n    pass\n"
            "print('MODULES', json.dumps(sorted(sys.modules)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    line = [x for x in done.stdout.splitlines() if x.startswith("MODULES ")]
    assert line, done.stdout + done.stderr
    return set(json.loads(line[-1][8:]))


@pytest.mark.parametrize("args", PLAIN + TYPED, ids=" ".join)
def test_a_command_to_the_daemon_imports_only_the_api_client(args, closed_api):
    modules = imported([*args, "--api", closed_api])
    ours = {m for m in modules if m.startswith("spacearm")}
    assert ours <= CLIENT_MODULES, f"spacearm {' '.join(args)} imports {sorted(ours - CLIENT_MODULES)}"
    allowed = {"pydantic", "pydantic_core", "annotated_types", "typing_inspection"} if args in TYPED else set()
    heavy = sorted(m for m in modules if m.split(".")[0] in HEAVY and m.split(".")[0] not in allowed)
    assert not heavy, f"spacearm {' '.join(args)} imports {heavy[:8]}"
    if args in PLAIN:      # the fast path: not even these (~5-10 ms each of an idle start)
        slow = sorted(SLOW_STDLIB & modules)
        assert not slow, f"spacearm {' '.join(args)} imports {slow}"


@pytest.mark.parametrize("args", [["--help"], [], ["oru", "--help"], ["kin", "--help"], ["hub", "--help"],
                                  ["kin", "fk", ARM, "ready"], ["status", "--help"]], ids=lambda a: " ".join(a) or "-")
def test_help_and_kinematics_never_import_scipy_stats(args):
    modules = imported(args)
    assert "scipy.stats" not in modules
    assert not any(m.startswith(("spacearm.offline", "spacearm.controller.daemon.daemon")) for m in modules)


def test_the_command_index_matches_what_the_modules_register():
    """console/command_index.py is what `spacearm --help` lists and which module a word loads:
    each word registered by its module alone, with the help its command really has."""
    full = typer.main.get_command(build_app())
    words = set(full.commands)
    assert words == set(COMMANDS), f"missing from the index: {words - set(COMMANDS)}; stale: {set(COMMANDS) - words}"
    for word, (module, text) in COMMANDS.items():
        alone = typer.main.get_command(build_app((module,)))
        assert word in alone.commands, f"{word}: not registered by console/commands/{module}.py"
        assert full.commands[word].get_short_help_str(limit=120) == text, word


@pytest.mark.parametrize("word", ["hub", "export", "oru", "status"])
def test_a_word_registered_alone_is_still_a_subcommand(word):
    """`spacearm hub --help` with only hub's module loaded: typer must not take the one
    command for the whole program (it then refused `hub` as an extra argument)."""
    from typer.testing import CliRunner
    result = CliRunner().invoke(build_app((COMMANDS[word][0],)), [word, "--help"])
    assert result.exit_code == 0, result.output
    assert f"spacearm {word}" in result.output or f"{word} [OPTIONS]" in result.output, result.output
