"""Controller-side device drivers: CANopen objects in, SI values out (and back)."""
