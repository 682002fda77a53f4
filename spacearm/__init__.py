"""spacearm: a hardware-in-the-loop controller stack for a space manipulator over CANopen."""
