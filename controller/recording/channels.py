"""The channels of a spacearm recording and their JSON schemas (Foxglove-readable).

/cycle   one message per control cycle: time, SYNC counter, commanded (position and
         velocity offset) and measured joint values, wrench, end-effector state, mode, cycle timing (SI units)
/events  state changes, protective stops and their reasons, device events
/stats   cycle statistics summary, once per second
"""
from __future__ import annotations

from typing import Any

NUMBER_ARRAY = {"type": "array", "items": {"type": "number"}}

CYCLE_SCHEMA: dict[str, Any] = {
    "title": "spacearm.Cycle",
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "controller time, s"},
        "sync": {"type": "integer", "description": "CANopen SYNC counter (1..240)"},
        "cycle": {"type": "integer", "description": "cycle number since start (gaps = skipped)"},
        "q_cmd": {**NUMBER_ARRAY, "description": "rad (m for a prismatic joint)"},
        "dq_cmd": {**NUMBER_ARRAY, "description": "rad/s (m/s), velocity offset (60B1h) sent with q_cmd; "
                                                  "absent in recordings made before it was recorded"},
        "q": {**NUMBER_ARRAY, "description": "rad (m for a prismatic joint)"},
        "dq": {**NUMBER_ARRAY, "description": "rad/s (m/s)"},
        "tau": {**NUMBER_ARRAY, "description": "N m (N along a prismatic joint)"},
        "wrench": {**NUMBER_ARRAY, "description": "fx fy fz (N) tx ty tz (N m)"},
        "end_effector": {"type": "string"},
        "state": {"type": "string"},
        "mode": {"type": "string"},
        "period_error": {"type": "number", "description": "s"},
        "execution": {"type": "number", "description": "s"},
        "io_wait": {"type": "number", "description": "s of execution spent waiting for this SYNC's TPDOs"},
        "missing": {"type": "array", "items": {"type": "string"},
                    "description": "nodes whose process data did not arrive this cycle (their values are the "
                                   "last received); absent when every node's arrived"},
        "extra": {"type": "object", "description": "further channels, name -> number"},
    },
    "required": ["t", "sync", "cycle", "q_cmd", "q", "dq", "tau", "wrench"],
}

EVENT_SCHEMA: dict[str, Any] = {
    "title": "spacearm.Event",
    "type": "object",
    "properties": {"t": {"type": "number"}, "kind": {"type": "string"}, "message": {"type": "string"},
                   "code": {"type": "string", "description": "FindingCode of a protective stop or finding"},
                   "node": {"type": "string"}, "joint": {"type": "string"}},
    "required": ["t", "kind", "message"],
}

STATS_SCHEMA: dict[str, Any] = {
    "title": "spacearm.CycleStats",
    "type": "object",
    "properties": {k: {"type": "number"} for k in (
        "cycles", "overruns", "skipped_cycles", "period_error_median", "period_error_p99",
        "period_error_max", "execution_median", "execution_p99", "execution_max",
        "compute_median", "compute_p99", "warnings", "errors")} | {
        "level": {"type": "string"},
        "overrun_causes": {"type": "object", "additionalProperties": {"type": "number"},
                           "description": "judged overruns by cause (controller/daemon/overrun_cause.py)"}},
}

CHANNELS = {"/cycle": CYCLE_SCHEMA, "/events": EVENT_SCHEMA, "/stats": STATS_SCHEMA}
