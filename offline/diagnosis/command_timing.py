"""How a recording's commands reached the drives: whether each carried its planned velocity
as the drives' velocity offset, which the replay must then add as the drives did.

The timeline of one row k of the daemon's recording (lockstep or real time, in-process bus or
the loopback hub; read from controller/daemon/daemon.py ``cycle_once`` and ``_record``,
controller/daemon/hardware.py ``read``/``write``, firmware_sim/runner.py ``_sync_step``,
joint_drive.py and plant.py):

1. The daemon sends SYNC k (``read``). On it the simulator latches, per drive, the target
   position 607Ah and velocity offset 60B1h that arrived before it, i.e. cycle k-1's
   (``on_sync_begin``); a CSP drive ramps its reference from the last target to the new one
   over the period, with velocity feed-forward step/period + the offset.
2. The plant advances one period in sub-steps (``Plant.step``); the servo torque of each
   sub-step is computed from the resolver reading at its start.
3. ``on_sync_end`` writes the actual values after the last sub-step: position 6064h (resolver
   reading at the end of the period, late by any feedback latency), velocity 606Ch (at the end
   of the period) and torque 6077h (the motor torque of the last sub-step, one sub-step older
   than the position, as a real drive reports its last current-loop value); ``send_tpdos``
   samples them into the SYNC's TPDOs. No TPDO is sampled from another period.
4. The daemon waits for SYNC k's TPDOs (lockstep: all of them), so q, dq and tau of row k are
   all the state after period k. The core computes command k from them; ``write`` sends its
   RPDOs, latched at SYNC k+1. Row k records this measurement beside command k.

So row k shows the plant after command k-1, for every channel alike: the convention of
``direct_sim.simulate``. Position and torque are not sampled at different rows.

What differs is the velocity offset. The daemon's moves (Ruckig joint moves, Cartesian and
resolved-rate paths, approaches) send the planned velocity with each target, and the
drive adds it to its own step/period feed-forward: with the test bed's 15 Hz, critically
damped servo the arm then leads its reference by 2 zeta / omega = 21 ms, about one row. The
recording keeps the targets only. Replayed without the offset, the position looks one row
early (the symptom an earlier version of this module re-indexed the commands for; that cured
the position, 8.3e-4 -> 7.5e-5 rad, but not the torque, whose servo share the offset changes
in every acceleration, and the viscous size came out 18-22 % low). Replayed with the offset
rebuilt from the targets, position and torque both match (``tests/diagnosis/
test_command_timing.py``). The offset is decided from the recording itself: the nominal
replay of the moving joints' positions with and without it; with it must halve the residual,
otherwise the recording is replayed as commanded (record-sim's trajectories send no offset).

Since the daemon records the offset it sends (``dq_cmd``, controller/daemon/daemon.py
``_record``), none of this guessing is needed for its recordings: the recorded offset is
replayed as sent (``simulate(dq_cmd=table.dq_cmd)``) and wins over the rebuilt one, which
stays for recordings made before, and other tools' CSVs.
"""
from __future__ import annotations

import numpy as np

from spacearm.firmware_sim.plant import PlantConfig
from spacearm.offline.diagnosis.direct_sim import ArmPlant, SimulationDiverged, simulate
from spacearm.offline.diagnosis.recording_io import RecordingTable

CLEAR_MARGIN = 0.5        # the offset must halve the position residual to be taken
MIN_TRAVEL = 1e-3         # rad: joints moving less say nothing about the offset


def with_velocity_offset(plant: PlantConfig, offset: bool = True) -> ArmPlant:
    """The plant replayed with (or without) the commands' planned velocity as the drives' offset."""
    if isinstance(plant, ArmPlant):
        return plant.model_copy(update={"planned_velocity_offset": offset})
    return ArmPlant(**dict(plant), planned_velocity_offset=offset)


def position_residual(table: RecordingTable, plant: PlantConfig, joints: list[int]) -> float:
    """RMS of the recorded minus the replayed positions of `joints` (rad)."""
    sim = simulate(plant, table.q_cmd, table.dt, q0=table.q[0], dq_cmd=table.dq_cmd, joints=joints)
    return float(np.sqrt(np.mean((table.q[:, joints] - sim.q) ** 2)))


def replay_plant(table: RecordingTable, nominal: PlantConfig) -> tuple[PlantConfig, str | None]:
    """The nominal plant driven as the recording's controller drove the drives (and a line
    saying so), or `nominal` unchanged (and None) when the commands sent no velocity offset
    or the recording cannot tell. A recording with the offsets it sent (``table.dq_cmd``) is
    replayed with those, not with rebuilt ones."""
    if table.dq_cmd is not None:
        sent = float(np.max(np.abs(table.dq_cmd), initial=0.0))
        return with_velocity_offset(nominal, False) if isinstance(nominal, ArmPlant) else nominal, (
            f"commands: the drives' velocity offset as recorded (dq_cmd, up to {sent:.3g} rad/s): replayed as sent"
            if sent > 0.0 else None)
    moving = [j for j in range(table.q.shape[1]) if np.ptp(table.q_cmd[:, j]) > MIN_TRAVEL]
    if not moving or len(table.t) < 20:
        return nominal, None
    try:
        plain = position_residual(table, with_velocity_offset(nominal, False), moving)
        offset = with_velocity_offset(nominal)
        with_offset = position_residual(table, offset, moving)
    except SimulationDiverged:
        return nominal, None
    if with_offset < CLEAR_MARGIN * plain:
        return offset, (f"commands: sent with their planned velocity as the drives' velocity offset (position "
                        f"residual {with_offset:.3g} rad with it, {plain:.3g} rad without): replayed so")
    return nominal, None
