"""When a recording's commands took effect: the row the replay should latch them at.

The replay assumes the daemon's cycle on real drives: the command recorded in row k is latched
at the next SYNC, so the measurement of row k+1 is the first to show it. A recording made
another way (another controller, or a simulator that latches a command as it arrives) shows
each command one row earlier; replayed with the wrong latching, every motion leads the
replay by one cycle and the diagnosis reports a position mismatch no physics explains.
The latching is read from the recording itself: the nominal replay of its moving joints'
positions under each candidate, the closer one wins by a clear margin, otherwise the
daemon's convention stays.
"""
from __future__ import annotations

import numpy as np

from spacearm.firmware_sim.plant import PlantConfig
from spacearm.offline.diagnosis.direct_sim import SimulationDiverged, simulate
from spacearm.offline.diagnosis.recording_io import RecordingTable

CLEAR_MARGIN = 0.5        # the earlier latching must halve the position residual to be taken
MIN_TRAVEL = 1e-3         # rad: joints moving less say nothing about timing


def commands_one_row_earlier(table: RecordingTable) -> RecordingTable:
    """The table re-indexed so that row k's command is the one its measurement first shows:
    command k+1 beside measurement k (the last row is dropped)."""
    shifted = table.rows(slice(0, len(table.t) - 1))
    shifted.q_cmd = table.q_cmd[1:].copy()
    return shifted


def align_commands(table: RecordingTable, nominal: PlantConfig) -> tuple[RecordingTable, str | None]:
    """The table with its commands latched where the recording shows them (and a line saying
    so), or the table unchanged (and None)."""
    moving = [j for j in range(table.q.shape[1]) if np.ptp(table.q_cmd[:, j]) > MIN_TRAVEL]
    if not moving or len(table.t) < 20:
        return table, None
    earlier = commands_one_row_earlier(table)

    def residual(t: RecordingTable) -> float:
        sim = simulate(nominal, t.q_cmd, t.dt, q0=t.q[0], joints=moving)
        return float(np.sqrt(np.mean((t.q[:, moving] - sim.q) ** 2)))
    try:
        as_daemon, as_arrived = residual(table), residual(earlier)
    except SimulationDiverged:
        return table, None
    if as_arrived < CLEAR_MARGIN * as_daemon:
        return earlier, (f"commands: each shows in the measurement of its own row, not the next "
                         f"(position residual {as_arrived:.3g} rad against {as_daemon:.3g} rad): replayed latched "
                         "one row earlier")
    return table, None
