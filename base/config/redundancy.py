"""Schema of a bus file's [bus.redundancy] table: bus redundancy on a redundant pair of lines
(a bus spec `A+B`; base/transport/redundant.py). Unused on one line.

The node-side values go into each node's redundancy object at bring-up (2E00h, see
base/canopen/redundancy_object.py); the heartbeat values replace [bus]'s on a pair.
"""
from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from spacearm.base.config.loader import StrictModel


class RedundancySettings(StrictModel):
    default_line: Literal["A", "B"] = Field(default="A", description="Bdefault (2E00h:1): the line a node starts on")
    toggle_time: int = Field(default=1, ge=1, le=255, description=(
        "Ttoggle (2E00h:2): master consumer times (master_heartbeat_timeout) without the master's "
        "heartbeat before a node toggles to the other line"))
    max_toggles: int = Field(default=8, ge=1, le=255, description=(
        "Ntoggle (2E00h:3): toggles without finding the master before a node stays where it is "
        "and takes its heartbeat-loss reaction"))
    master_heartbeat_period: float = Field(default=0.02, ge=0.005, le=1.0, description=(
        "s; on a pair the controller's heartbeat runs at this period: the nodes follow it to the "
        "other line, so it sets how fast they do"))
    master_heartbeat_timeout: float = Field(default=0.06, ge=0.01, le=3.0, description=(
        "s; on a pair the nodes' consumer time for the controller's heartbeat (1016h:1)"))

    @model_validator(mode="after")
    def _timeout_after_period(self) -> "RedundancySettings":
        if self.master_heartbeat_timeout < 2 * self.master_heartbeat_period:
            raise ValueError(f"master_heartbeat_timeout ({self.master_heartbeat_timeout} s) must be at least "
                             f"two master heartbeat periods ({2 * self.master_heartbeat_period} s): one late "
                             "heartbeat would move a node to the other line")
        return self

    @property
    def default_line_index(self) -> int:
        return "AB".index(self.default_line)

    def switch_time(self) -> float:
        """s from the master's last heartbeat a node heard to its toggle (Lely's rule)."""
        return self.toggle_time * self.master_heartbeat_timeout
