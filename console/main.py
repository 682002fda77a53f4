"""Entry point of the `spacearm` command: a typer app with one subcommand group per module.

`main()` (the installed script) sends the plain `stop`, `status`, `enable`, `disable`, `reset`
without typer (console/quick.py), and otherwise registers only the module the typed command needs when it is
one of the light operator commands: `stop`, `status`, `enable`, ... import the API client and
nothing of the controller stack, so a stop reaches the daemon in tens of milliseconds instead
of the seconds scipy and the planner take to import (bench/bench_console.py measures it).
Anything else (help, heavy commands, commands added by other modules) builds the full app.
`app` (module attribute, for tests and `typer` tooling) is always the full app.
"""
from __future__ import annotations

import importlib
import os
import sys
TYPE_CHECKING = False   # typing itself is ~10 ms of a stop's start-up: annotations only
if TYPE_CHECKING:
    from typing import Iterable

    import typer

# Subcommand modules; each defines register(app). Optional ones may be absent while
# their issue is in progress, so a missing module is skipped rather than breaking the CLI.
COMMAND_MODULES = ("config", "kinematics", "demo", "daemon", "operate", "export", "calibrate", "sim", "hub",
                   "record_sim", "diagnose", "web", "oru", "approach", "arm", "campaign", "bus")

# Commands whose module is light (imports only the client). Every known word is now
# registered alone (console/command_index.py); kept for callers that read it.
LIGHT_COMMANDS = {name: "operate" for name in ("status", "watch", "enable", "disable", "reset", "stop",
                                                 "jog", "move", "control", "record")}


def index_app() -> "typer.Typer":
    """`spacearm` / `spacearm --help`: the same options and command list as the full app, from
    console/command_index.py, without importing a command module (the diagnosis alone pulls
    in scipy.stats)."""
    from spacearm.console.command_index import COMMANDS
    app = build_app(())
    for word, (_, text) in COMMANDS.items():
        app.command(word, help=text)(lambda: None)
    return app


def build_app(modules: Iterable[str] = COMMAND_MODULES) -> "typer.Typer":
    import typer   # here: the quick commands never import it

    app = typer.Typer(
        name="spacearm",
        help="Hardware-in-the-loop controller stack for a space-station manipulator (CANopen).",
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
    )

    @app.callback()
    def group() -> None:   # a group even with one command registered: `spacearm hub ...` names it
        pass

    for module_name in modules:
        try:
            module = importlib.import_module(f"spacearm.console.commands.{module_name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"spacearm.console.commands.{module_name}":
                raise
            continue
        module.register(app)
    return app


def _command_of(args: list[str]) -> str | None:
    """The subcommand typed (first word that is not an option; no top-level option takes a value)."""
    return next((a for a in args if not a.startswith("-")), None)


_full_app: "typer.Typer | None" = None


def __getattr__(name: str):
    global _full_app
    if name == "app":
        if _full_app is None:
            _full_app = build_app()
        return _full_app
    raise AttributeError(name)


# `stop` asks for SCHED_FIFO at this priority for its few milliseconds of life: on a loaded
# machine a new process otherwise queues behind every CPU-bound one before it can even import
# the client (bench/bench_console.py: p99 ~1 s beside two CPU hogs). Below the control path
# (daemon, simulator, hub at 50), so it never delays a cycle; refused without CAP_SYS_NICE.
# SPACEARM_STOP_RT_PRIORITY=0 turns it off (the benchmark compares both).
STOP_RT_PRIORITY = 20


def main(argv: list[str] | None = None) -> None:
    """Run one command under the error contract (console/errors.py) and exit with its code."""
    try:
        _main(argv)
        sys.stdout.flush()
    except BrokenPipeError:
        # The reader went away (`status --json | head -c 600`): what it wanted it has; no
        # traceback, and none either from the interpreter's own flush of the dead pipe at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        raise SystemExit(0) from None


def _main(argv: list[str] | None) -> None:
    args = sys.argv[1:] if argv is None else list(argv)
    if args[:1] == ["stop"] and argv is None:
        from spacearm.base.runtime.priority import use_fifo
        try:
            priority = int(os.environ.get("SPACEARM_STOP_RT_PRIORITY", STOP_RT_PRIORITY))
            use_fifo(priority)
        except ValueError:
            pass           # a bad setting must not keep a stop from going out
    from spacearm.console import quick

    plain = quick.parse(args)
    if plain is not None:
        quick.run(*plain)
        raise SystemExit(0)
    call = quick.parse_call(args)
    if call is not None:
        call()
        raise SystemExit(0)

    from typer._click.exceptions import UsageError
    from typer.exceptions import Abort, Exit

    from spacearm.console.errors import EXIT_FAILED, EXIT_USAGE, classify, report

    as_json = "--json" in args
    command = _command_of(args)
    from spacearm.console.command_index import module_of
    module = module_of(command)
    app = index_app() if command is None else build_app((module,) if module else COMMAND_MODULES)
    try:
        code = app(args=args, prog_name="spacearm", standalone_mode=False)
    except UsageError as exc:
        if not args or type(exc).__name__ == "NoArgsIsHelpError":
            # `spacearm` or `spacearm move` alone: show the help, as the user asked for nothing
            print(exc.ctx.get_help() if exc.ctx else "spacearm --help", file=sys.stderr)
            raise SystemExit(EXIT_USAGE) from None
        where = f" (see `{exc.ctx.command_path} --help`)" if exc.ctx else ""
        raise report(exc.format_message() + where, "bad_usage", EXIT_USAGE, as_json) from None
    except (Abort, KeyboardInterrupt):
        raise report("interrupted", "interrupted", 130, as_json) from None
    except Exit as exc:
        raise SystemExit(exc.exit_code) from None
    except SystemExit:
        raise
    except Exception as exc:   # a command without friendly_errors, or a bug: still one line
        known = classify(exc)
        if known is not None:
            raise report(*known, as_json) from None
        if os.environ.get("SPACEARM_TRACEBACK"):
            raise
        raise report(f"{type(exc).__name__}: {exc} (a bug; SPACEARM_TRACEBACK=1 shows the traceback)",
                     "internal_error", EXIT_FAILED, as_json) from None
    raise SystemExit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
