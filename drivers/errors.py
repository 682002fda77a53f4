"""Exceptions and events of the controller-side drivers. Messages name the node."""
from __future__ import annotations

from dataclasses import dataclass, field
import time



class DriverError(Exception):
    """Base of every error the drivers raise."""


class BootError(DriverError):
    """Network bring-up failed (node missing, wrong device, configuration refused)."""


class SdoError(DriverError):
    """An SDO transfer was aborted by the node (``code`` is the CiA 301 abort code)."""

    def __init__(self, node_label: str, action: str, index: int, subindex: int, code: int):
        self.node_label, self.index, self.subindex, self.code = node_label, index, subindex, code
        self.meaning = abort_text(code)
        super().__init__(f"{node_label}: SDO {action} 0x{index:04X}:{subindex:02X} aborted with "
                         f"0x{code:08X} ({self.meaning})")


class SdoTimeoutError(DriverError):
    """The node did not answer an SDO request."""


class FaultResetError(DriverError):
    """A fault reset did not clear the fault."""


# EMCY error codes -> text: one table (base/canopen/codes.py)
from spacearm.base.canopen.codes import EMCY_TEXT, abort_text, emcy_text  # noqa: E402,F401


@dataclass
class NetworkEvent:
    """Something the controller must act on. kind is one of:
    heartbeat_lost, heartbeat_restored, bootup (unexpected reboot), nmt_state, emcy,
    emcy_reset, fault_reset_failed, fault_cleared, tpdo_timeout, tpdo_missing (a mapped TPDO
    of a live node absent for bus.tpdo_loss_cycles SYNCs: a fault like heartbeat_lost),
    late_cycle (the master was starved: heartbeat silence in that window not counted; informational)."""
    kind: str
    node: str
    node_id: int
    message: str
    code: int = 0
    time: float = field(default_factory=time.monotonic)

    def __str__(self) -> str:
        return f"[{self.kind}] {self.message}"
