"""Contact world of the ORU cell: the plant's `Environment` (see world.py)."""
from spacearm.firmware_sim.contact.config import ContactConfig
from spacearm.firmware_sim.contact.world import ContactWorld, build_contact_world

__all__ = ["ContactConfig", "ContactWorld", "build_contact_world"]
