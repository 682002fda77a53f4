class PlanningError(ValueError):
    """A requested motion cannot be planned (outside limits, unreachable, bad input)."""
