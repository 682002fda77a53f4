"""What a refused API request means, as a stable code beside the sentence.

Every error answer of the command API is `{"ok": false, "error": MESSAGE, "code": CODE}`.
Consoles, the browser console and the tests branch on the code; the message is for people and
may be reworded at any time.
"""
from __future__ import annotations

from enum import Enum


class ErrorCode(str, Enum):
    BAD_REQUEST = "bad_request"            # not JSON, not an object, wrong id/cmd/args types
    UNAUTHORIZED = "unauthorized"          # missing or wrong token on an exposed API
    UNKNOWN_COMMAND = "unknown_command"
    BAD_ARGUMENT = "bad_argument"          # an argument is missing, of the wrong type or out of range
    LEASE_HELD = "lease_held"              # another console holds control: watch only
    NO_LEASE = "no_lease"                  # nobody holds control: take it first
    PROTECTIVE_STOP = "protective_stop"    # a protective stop is active: reset first
    NOT_ENABLED = "not_enabled"            # the arm is disabled or still enabling
    DRIVE_FAULT = "drive_fault"            # a drive is in fault (right after a reset: try again)
    BUSY = "busy"                          # a motion is in progress
    MOVED = "moved_while_planning"         # the arm moved while the motion was planned: send it again
    PLANNING_REFUSED = "planning_refused"  # unreachable, joint limits on the path, near a singularity
    UNAVAILABLE = "unavailable"            # the daemon has no such feature here (no camera, no ORU cell)
    NOT_RUNNING = "not_running"            # nothing to pause, resume or abort
    CYCLE_TIMEOUT = "cycle_timeout"        # the control cycle did not take the command in time
    RECORDING = "recording"                # a recording could not be started or stopped
    INTERNAL = "internal_error"            # a bug: the command failed, the cycle went on
    # said by the console's client, not by the daemon
    NO_CONNECTION = "no_connection"        # the daemon cannot be reached, or the connection was lost
    BAD_ANSWER = "bad_answer"              # what answered is not a spacearm daemon

    def __str__(self) -> str:
        return self.value


class CodedError(Exception):
    """An exception that carries its ErrorCode (base of ApiError, CommandRefused, LeaseError)."""

    default_code = ErrorCode.INTERNAL

    def __init__(self, message: str, code: ErrorCode | None = None):
        super().__init__(message)
        self.code = ErrorCode(code) if code is not None else self.default_code
