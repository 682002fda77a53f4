from enum import Enum


class PlanningFailure(str, Enum):
    """Which check a refused plan failed, so callers need not read the message."""

    REQUEST = "request"            # malformed input: wrong length, non-finite, bad frame or speed
    JOINT_LIMITS = "joint_limits"  # a joint would leave its position or velocity limits
    REACHABILITY = "reachability"  # the goal is beyond reach or the straight path cannot get there
    PLANNER = "planner"            # the trajectory generator itself failed


class PlanningError(ValueError):
    """A requested motion cannot be planned (outside limits, unreachable, bad input)."""

    def __init__(self, message: str, kind: PlanningFailure = PlanningFailure.REQUEST) -> None:
        super().__init__(message)
        self.kind = PlanningFailure(kind)
