"""The direct simulation path: the firmware_sim plant driven cycle by cycle without a bus.

Same plant (``spacearm.firmware_sim.plant``), same drive servo law (``spacearm.firmware_sim.joint_drive.servo_torque``)
and the same CSP interpolation, scaling and reporting as the CAN path, minus the CANopen
frames: a 5-minute recording replays in seconds instead of minutes. Command timing matches
the daemon: the target (and velocity offset) written in cycle k-1 is latched at SYNC k, the
plant advances one period, and what the drives report after it is the measurement of row k
(the full timeline: ``command_timing.py``).
``tests/diagnosis/test_direct_vs_can.py`` checks both paths give the same recording.

Torque limit, position limits and the velocity clamp are the drives': the bus file's, or, for
a plant made with ``on_arm_drives``, the arm file's ``[joints.drive]`` and joint limits applied
to them exactly as the daemon applies them at bring-up (``with_drive_limits``). Drive faults
(following error) are not modelled here: a replay that would fault says so through
``SimTraces.following_error_max``, beside the arm's window.

A prismatic joint (plant ``kind``, set from the arm file's joint type by ``on_arm_drives``)
is driven in its own units: m, N. Its drive's position and torque scaling go through the
screw (the plant's gear ratio, motor rad per m), where a real CiA 402 drive has 6091h and
the feed constant 6092h.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from pathlib import Path

import numpy as np
from pydantic import Field

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, BusConfig, JointSettings, NodeConfig, load_bus_config
from spacearm.base.config.errors import ConfigError
from spacearm.controller.daemon.hardware import with_drive_limits
from spacearm.firmware_sim.joint_drive import servo_torque
from spacearm.firmware_sim.simcore import SERVO_CSP
from spacearm.firmware_sim.plant import JointModel, JointParams, Plant, PlantConfig

FT_FORCE_QUANTUM = 0.01      # N: 100 counts/N (2201h default)
FT_TORQUE_QUANTUM = 0.001    # N m: 1000 counts/N m (2202h default)


class SimulationDiverged(ValueError):
    """The plant could not be integrated over the recording (a joint too light or too stiff for
    the explicit step, or an effect so strong that the servo goes unstable)."""


@dataclass
class SimTraces:
    """What the controller would have recorded, one row per cycle (SI)."""
    t: np.ndarray
    q_cmd: np.ndarray       # (N, n)
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray         # joint side, N m (N on a prismatic joint)
    wrench: np.ndarray      # (N, 6)
    following_error_max: float = 0.0     # rad (m), largest |reference - position| over the replay
    following_error_window: float = math.inf   # rad (m), the arm's smallest window (supervision), if known


def joint_settings(bus_config: BusConfig | str | None = None, n: int | None = None) -> list[JointSettings]:
    """Drive settings per joint from the bus configuration; for an arm with more joints than
    the configuration has drives, the last drive's settings stand in for the extra ones."""
    config = bus_config if isinstance(bus_config, BusConfig) else _bus_file(bus_config or DEFAULT_BUS_CONFIG)
    settings = [node.joint or JointSettings() for node in config.joints] or [JointSettings()]
    return settings + [settings[-1]] * max(0, (n or 0) - len(settings))


def _bus_file(path: str | Path) -> BusConfig:
    """load_bus_config once per version of the file (its configs are frozen): every replay asks
    for the drives' settings, a few ms of TOML each, and a diagnosis replays a hundred times."""
    path = Path(path).resolve()
    stat = path.stat()
    return _loaded_bus_file(path, stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=8)
def _loaded_bus_file(path: Path, mtime_ns: int, size: int) -> BusConfig:
    return load_bus_config(path)


class ArmPlant(PlantConfig):
    """A plant file's physics on one arm's drives, as the diagnosis replays it: the drive
    settings carry the arm file's velocity and torque limits and joint limits. Every copy of
    it (``model_copy``: each fitted variant) keeps them; they are not written to plant files.

    ``planned_velocity_offset``: the recording's controller sent each command's planned
    velocity as the drives' velocity offset (60B1h), as the daemon's moves do. Recordings
    made before the daemon recorded the offset (``dq_cmd``) hold the positions only, so the
    replay rebuilds it from them (``planned_velocity``); ``offline/diagnosis/command_timing.py``
    decides from the recording whether it was sent. A recorded ``dq_cmd`` passed to
    ``simulate`` wins over this flag."""
    drives: list[JointSettings] = Field(default_factory=list, exclude=True)
    following_error: list[float] = Field(default_factory=list, exclude=True)
    planned_velocity_offset: bool = Field(default=False, exclude=True)


def planned_velocity(q_cmd: np.ndarray, dt: float) -> np.ndarray:
    """The velocity of the plan the commands were sampled from, at each command (N, n): the
    five-point central difference, exact on the jerk-limited (piecewise cubic) moves away
    from their jerk switches; the ends repeat the first and last command."""
    q = np.asarray(q_cmd, float)
    p = np.concatenate([q[:1], q[:1], q, q[-1:], q[-1:]])
    return (-p[4:] + 8.0 * p[3:-1] - 8.0 * p[1:-3] + p[:-4]) / (12.0 * dt)


def on_arm_drives(plant: PlantConfig, arm_file: str | Path, bus_config: BusConfig | str | None = None) -> ArmPlant:
    """`plant` driven by the arm's drives: the bus file's drive model (scaling, rated torque),
    one drive per arm joint, limited by the arm file as the daemon's bring-up limits them.
    The arm file's joint types set the plant joints' kind (prismatic: m, N)."""
    arm = load_arm_config(arm_file)
    n = len(arm.joints)
    plant = with_kinds(plant, [j.type for j in arm.joints], str(arm_file))
    padded = BusConfig(nodes=[NodeConfig(name=f"joint_{i + 1}", node_id=i + 1, device="joint_drive", joint=s)
                              for i, s in enumerate(joint_settings(bus_config, n)[:n])])
    limited = with_drive_limits(padded, [j.limits.lower for j in arm.joints], [j.limits.upper for j in arm.joints],
                                [j.drive for j in arm.joints])
    drives = [node.joint for node in limited.joints]
    for i, joint in enumerate(arm.joints):
        params = plant.joint_params(i)
        if params.prismatic:
            # the drive's force limit (N) reaches the motor through the screw, not the bus file's gear
            drives[i] = drives[i].model_copy(update={"max_torque": min(
                float(joint.drive.torque) / rated_joint_torque(drives[i], params), 3.0)})
    return ArmPlant(**dict(plant), drives=drives, following_error=[j.drive.following_error for j in arm.joints])


def with_kinds(plant: PlantConfig, kinds: list[str], source: str) -> PlantConfig:
    """The plant with each joint's kind taken from the arm; a plant file that states the
    other kind for a joint is refused (one line)."""
    joints = [plant.joint_params(i) for i in range(max(len(kinds), len(plant.joints)))]
    changed = False
    for i, kind in enumerate(kinds):
        if joints[i].kind == kind:
            continue
        if "kind" in joints[i].model_fields_set:
            raise ConfigError(f"joint {i + 1}: the plant file says kind = {joints[i].kind}, the arm file {source} "
                              f"says {kind} (give the recorded arm's own file, --arm)")
        joints[i] = joints[i].model_copy(update={"kind": kind})
        changed = True
    return plant.model_copy(update={"joints": joints}) if changed else plant


def rated_joint_torque(settings: JointSettings, params: JointParams) -> float:
    """N m (N if prismatic) at the joint for 1000 per mille of 6077h. A prismatic joint's
    drive scales through its screw: its feed constant where the bus file gives one (as on the
    CAN path), else the plant's gear ratio (rad per m)."""
    if params.prismatic and not settings.linear:
        return settings.rated_torque * params.gear_ratio
    return settings.rated_joint_torque


def increments_per_unit(settings: JointSettings, params: JointParams) -> float:
    """Position increments per rad (per m if prismatic) at the joint."""
    if params.prismatic and not settings.linear:
        return settings.encoder_increments / settings.motor_revolutions * params.gear_ratio / (2.0 * math.pi)
    return settings.increments_per_rad


def drive_settings(config: PlantConfig, n: int) -> list[JointSettings]:
    """The drive settings a replay of `config` uses for n joints (the arm's, if it carries them)."""
    if isinstance(config, ArmPlant) and config.drives:
        return config.drives + [config.drives[-1]] * max(0, n - len(config.drives))
    return joint_settings(n=n)


class _CspDrive:
    """One drive in CSP: linear interpolation of the latched target across the SYNC period."""

    def __init__(self, joint: JointModel, settings: JointSettings, limits: tuple[float, float], dt: float):
        self.joint = joint
        self.k = increments_per_unit(settings, joint.params)
        self.rated_motor = settings.rated_torque
        self.rated_joint = rated_joint_torque(settings, joint.params)
        self.vmax = settings.max_velocity
        self.lo, self.hi = limits
        self.dt = dt
        self.q_start = self.q_end = self.q_ref = joint.q_measured
        self.v_ff = 0.0
        joint.brake_engaged = False
        joint.max_motor_torque = settings.max_torque * settings.rated_torque
        servo = joint.controller = self._servo      # one bound method: the core checks it `is` the controller
        # the same servo law for the whole period, as the plant runs a period in one call (a
        # rigid gear's in the compiled core, a loose or elastic gear's in firmware_sim.two_mass;
        # the same bits as _servo sub-step by sub-step): the per-sub-step Python calls were most
        # of a diagnosis's replay time
        joint.period_servo = (servo, self._period_law)

    def latch(self, target: float, velocity_offset: float) -> None:
        k, dt = self.k, self.dt
        target = round(target * k) / k                 # 607Ah increments
        clamped = min(self.hi, max(self.lo, target))
        self.q_start = self.q_ref
        step = clamped - self.q_start
        if abs(step) > self.vmax * dt:
            step = math.copysign(self.vmax * dt, step)
        self.q_end = self.q_start + step
        self.v_ff = step / dt + round(velocity_offset * k) / k

    def _servo(self, s: float, q_meas: float, qd: float) -> float:
        self.q_ref = self.q_start + s * (self.q_end - self.q_start)
        return servo_torque(self.joint, self.q_ref, self.v_ff, q_meas, qd)

    def _period_law(self) -> tuple:
        # torque offset -0.0: the plant's law adds it, _servo adds nothing, and x + -0.0 is x to
        # the bit where x + 0.0 turns a -0.0 torque into +0.0
        return SERVO_CSP, self.q_start, self.q_end, self.v_ff, -0.0, self._end_period

    def _end_period(self, q_ref: float, v_ref: float) -> None:
        self.q_ref = q_ref

    def report(self) -> tuple[float, float, float]:
        j, k = self.joint, self.k
        per_mille = max(-32768, min(32767, round(j.torque_reported / self.rated_motor * 1000.0)))   # 6077h
        return round(j.q_reported * k) / k, round(j.qd_reported * k) / k, per_mille / 1000.0 * self.rated_joint


def simulate(config: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray | None = None,
             dq_cmd: np.ndarray | None = None, settings: list[JointSettings] | None = None,
             limits: list[tuple[float, float]] | None = None, joints: list[int] | None = None,
             t0: float = 0.0, wrench: bool = True) -> SimTraces:
    """Replay commanded positions (N, n) through the plant; row k reports the plant after the
    command of row k-1. `joints` simulates only those columns (joints are independent unless
    an environment couples them), which is what the diagnosis does per candidate effect.
    `wrench=False` leaves the F/T channel at zero: the per-joint replays of the fits never
    read it, and reading and rounding it every row cost about a tenth of such a replay (the
    F/T sensor's noise has a generator of its own, so the joints' traces are the same)."""
    q_cmd = np.atleast_2d(np.asarray(q_cmd, float))
    rows, n = q_cmd.shape
    wanted = list(range(n)) if joints is None else list(joints)
    # coupled dynamics (an imported arm's rigid body, a contact world) move every joint together:
    # all of them are simulated and the wanted columns returned
    coupled = config.rigid_body is not None or config.contact is not None
    index = list(range(n)) if coupled else wanted
    settings = settings or drive_settings(config, n)
    if len(settings) < n:
        settings = list(settings) + [settings[-1]] * (n - len(settings))
    if limits is None and isinstance(config, ArmPlant) and config.drives:
        limits = [(s.lower, s.upper) for s in settings]     # 607Dh, as the daemon configures it
    params = [config.joint_params(i) for i in index]
    start = q_cmd[0] if q0 is None else np.asarray(q0, float)
    params = [p.model_copy(update={"initial_position": float(start[i])}) for i, p in zip(index, params)]
    plant = Plant.create(len(index), config.model_copy(update={"joints": params}))
    plant.time = t0
    drives = [_CspDrive(joint, settings[i], limits[i] if limits else (-math.inf, math.inf), dt)
              for joint, i in zip(plant.joints, index)]
    if plant.environment is None and plant.dynamics is None:
        # nothing reads the end effector's grip and screw here (no contact world): stepping them,
        # ten sub-steps a row, cost a sixth of a gear fit's replays
        plant.ee = None
    fe = 0.0
    cols = q_cmd[:, index]
    if dq_cmd is not None:
        vel = np.asarray(dq_cmd, float)[:, index]
    elif isinstance(config, ArmPlant) and config.planned_velocity_offset:
        vel = planned_velocity(cols, dt)
    else:
        vel = np.zeros_like(cols)
    # Python floats and lists, not numpy scalars and element writes, on the per-row path (the
    # same values): after the plant's own step, those were most of a replay's cost
    commands, velocities = cols.tolist(), vel.tolist()
    previous, previous_v = commands[0], [0.0] * len(index)
    reported, readings = [], []
    for r in range(rows):
        for drive, target, offset in zip(drives, previous, previous_v):
            drive.latch(target, offset)
        try:
            plant.step(dt)
            reported.append([drive.report() for drive in drives])
        except (OverflowError, ValueError) as exc:     # round() of an infinite or NaN state
            raise SimulationDiverged(f"the simulated plant diverges at t = {t0 + dt * (r + 1):.3g} s "
                                     f"({type(exc).__name__})") from None
        for drive in drives:      # max(): the largest, the first of equals, never a NaN
            error = abs(drive.q_ref - drive.joint.q_measured)
            if error > fe:
                fe = error
        if wrench:
            readings.append(plant.ft_reading())
        previous, previous_v = commands[r], velocities[r]
    traces = np.array(reported, float).reshape(rows, len(index), 3)
    q, dq, tau = (np.ascontiguousarray(traces[:, :, i]) for i in range(3))
    ft = np.zeros((rows, 6))
    if wrench:
        w = np.array(readings, float).reshape(rows, 6)
        ft[:, :3] = np.round(w[:, :3] / FT_FORCE_QUANTUM) * FT_FORCE_QUANTUM
        ft[:, 3:] = np.round(w[:, 3:] / FT_TORQUE_QUANTUM) * FT_TORQUE_QUANTUM
    t = t0 + dt * np.arange(1, rows + 1)
    window = min((config.following_error[i] for i in index if i < len(config.following_error)), default=math.inf) \
        if isinstance(config, ArmPlant) else math.inf
    keep = [index.index(i) for i in wanted]
    return SimTraces(t, cols[:, keep].copy(), q[:, keep], dq[:, keep], tau[:, keep], ft, fe, window)


def replayed_torque(config: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray, j: int,
                    dq_cmd: np.ndarray | None = None) -> np.ndarray | None:
    """Joint j's torque replayed alone on `config`; None where the explicit step diverges (a
    fitted law can make a light joint's step unstable) or gives non-finite values."""
    try:
        with np.errstate(all="raise"):
            sim = simulate(config, q_cmd, dt, q0=q0, joints=[j], dq_cmd=dq_cmd, wrench=False)
    except (OverflowError, FloatingPointError, ValueError):
        return None
    return sim.tau[:, 0] if np.all(np.isfinite(sim.tau)) else None
