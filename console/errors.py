"""Turn expected failures into one-line messages and exit codes, never tracebacks."""
from __future__ import annotations

import functools
import sys
from typing import Callable, TypeVar

from spacearm.base.config.errors import ConfigError

F = TypeVar("F", bound=Callable)

EXIT_USAGE = 2
EXIT_FAILED = 1


class CommandFailed(Exception):
    """A command could not do what was asked; the message is shown to the operator, the code
    (the daemon's ErrorCode value, or None for the console's own checks) is what code branches on."""

    def __init__(self, message: str, code: str | None = None):
        super().__init__(message)
        self.code = code


def friendly_errors(func: F) -> F:
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except ConfigError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise SystemExit(EXIT_USAGE) from None
        except CommandFailed as exc:
            print(f"error[{exc.code}]: {exc}" if exc.code else f"error: {exc}", file=sys.stderr)
            raise SystemExit(EXIT_FAILED) from None
    return wrapper  # type: ignore[return-value]
