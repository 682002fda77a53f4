"""Contact trials and the direct (bus-free) controller-plant loop."""
