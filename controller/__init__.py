"""spacearm controller: kinematics, planning, control, the daemon and its tools."""
