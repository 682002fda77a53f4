"""Trajectory planning: jerk-limited joint moves (Ruckig) and Cartesian paths."""
