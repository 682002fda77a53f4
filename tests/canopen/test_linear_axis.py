"""A linear axis over CANopen: the ORU test bed's rail (configs/bus/oru_testbed_on_rail.toml,
joint 1) scaled with the CiA 402 feed constant 6092h, in metres and newtons on both ends.

The rail: 10 mm lead screw driven 1:1, 10 000 increments per motor revolution (1 um each),
rated motor torque 3.2 N m = 2011 N along the rail; the plant lays it on a 30 deg ramp, so
245.25 N of the 50 kg slide's weight pulls toward -q, with 20 N Coulomb friction."""
from __future__ import annotations

import math
from contextlib import contextmanager
from pathlib import Path

import pytest

from spacearm.base.canopen import od
from spacearm.base.canopen.axis_scale import AxisScale
from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.bus import JointSettings, check_axis_kinds, load_bus_config
from spacearm.base.config.errors import ConfigError
from spacearm.controller.daemon.hardware import with_drive_limits
from spacearm.drivers.devices import JointDriver
from spacearm.drivers.network import ArmNetwork
from spacearm.firmware_sim.plant import load_plant_config
from spacearm.firmware_sim.runner import Simulator

ROOT = Path(__file__).resolve().parents[2]
ARM = ROOT / "configs/arm/oru_testbed_on_rail.toml"
BUS = ROOT / "configs/bus/oru_testbed_on_rail.toml"
PLANT = ROOT / "configs/plant/oru_testbed_on_rail.toml"
RATED_FORCE = 3.2 * 2 * math.pi / 0.01          # N along the rail per 1000 per mille of 6077h


def rail_hold(plant_file: Path = PLANT) -> tuple[float, float, float]:
    """(force at rest lowest, highest, servo stiffness N/m) of the plant's rail: the slide's
    weight along the ramp plus or minus its static friction, held by the drive's PD servo
    (stiffness J w^2 with J the carriage plus the motor reflected through the screw)."""
    p = load_plant_config(plant_file).joint_params(0)
    along = p.gravity_torque * math.cos(p.gravity_angle)
    stiffness = (p.motor_inertia * p.gear_ratio ** 2 + p.link_inertia) * (2 * math.pi * p.servo_bandwidth_hz) ** 2
    return along - p.coulomb_friction, along + p.coulomb_friction, stiffness


def test_rotary_scale_is_the_old_formula_bit_for_bit():
    s = JointSettings()
    assert s.increments_per_rad == (1 << 20) / 1 * 100 / 1 / (2.0 * math.pi)
    assert s.rated_joint_torque == 1.5 * 100
    assert [i for i, _, _ in s.scale.wire_objects()] == [0x608F, 0x608F, 0x6091, 0x6091, 0x6076]   # no 6092h


def test_linear_scale_from_the_feed_constant():
    rail = load_bus_config(BUS).joints[0].joint
    assert rail.linear and rail.scale.feed == 10_000 and rail.scale.feed_revolutions == 1
    assert rail.increments_per_rad == pytest.approx(1.0e6)             # 1 um per increment
    assert rail.rated_joint_torque == pytest.approx(RATED_FORCE)       # F = T gear 2 pi / lead
    assert (od.FEED_CONSTANT, 1, 10_000) in rail.scale.wire_objects()
    # the drive's own reported values win: a 5 mm lead and 2^17 increments
    reported = rail.scale.with_reported({(od.FEED_CONSTANT, 1): 5000, (od.POSITION_ENCODER_RESOLUTION, 1): 1 << 17})
    assert reported.per_unit == pytest.approx((1 << 17) / 0.005)
    assert reported.rated_joint == pytest.approx(3.2 * 2 * math.pi / 0.005)
    assert AxisScale(1, 1, 1, 1, 1.0).with_reported({(od.FEED_CONSTANT, 1): 5000}).feed is None   # rotary stays


@pytest.mark.parametrize("bad, message", [
    ({"feed_constant": 0.0100005}, "not a whole number of micrometres"),
    ({"feed_constant": 0.0}, "greater than or equal"),
])
def test_bad_feed_constants_are_refused(bad, message):
    with pytest.raises(ValueError, match=message):
        JointSettings(**bad)


def test_axis_kind_mismatch_between_arm_and_bus_is_one_line():
    arm = load_arm_config(ARM)
    kinds = [j.type for j in arm.joints]
    check_axis_kinds(load_bus_config(BUS), kinds, str(ARM))
    rotary_bus = load_bus_config(ROOT / "configs/bus/arm.toml")
    seven = rotary_bus.model_copy(update={"nodes": [rotary_bus.nodes[0].model_copy(update={"name": "rail"})]
                                          + rotary_bus.nodes})
    with pytest.raises(ConfigError, match="joint 1 is prismatic .* has no \\[nodes.joint\\] feed_constant") as info:
        check_axis_kinds(seven, kinds, str(ARM))
    assert "\n" not in str(info.value)
    with pytest.raises(ConfigError, match="joint 1 is revolute .* has a feed_constant"):
        check_axis_kinds(load_bus_config(BUS), ["revolute"] * 7, "six.toml")


def _limited(bus_path: Path = BUS):
    arm = load_arm_config(ARM)
    return with_drive_limits(load_bus_config(bus_path), [j.limits.lower for j in arm.joints],
                             [j.limits.upper for j in arm.joints], [j.drive for j in arm.joints])


def test_the_arm_file_limits_reach_the_rail_drive_in_metres():
    rail = _limited().joints[0].joint
    assert (rail.lower, rail.upper) == (pytest.approx(-0.05), pytest.approx(1.05))
    assert rail.max_velocity == 0.25 and rail.following_error_window == 0.005
    assert rail.max_torque * rail.rated_joint_torque == pytest.approx(2000.0)     # N through the screw
    writes = {(i, s): v for i, s, v in JointDriver(_limited().joints[0], _limited().bus, _od()).config_writes()}
    assert writes[(od.FOLLOWING_ERROR_WINDOW, 0)] == 5000                          # 5 mm in um
    assert writes[(od.SOFTWARE_POSITION_LIMIT, 2)] == 1_050_000
    assert writes[(od.MAX_PROFILE_VELOCITY, 0)] == 250_000


def _od():
    import canopen
    return canopen.import_od(str(load_bus_config(BUS).joints[0].eds_path), 1)


@contextmanager
def rail_on(vbus: str, bus_path: Path = BUS):
    """The simulated rail arm and our master on one virtual bus, the arm file's limits applied."""
    cfg = _limited(bus_path)
    sim = Simulator(vbus, cfg, PLANT).start()
    net = ArmNetwork(vbus, cfg)
    try:
        yield net, sim
    finally:
        net.close()
        sim.stop()


@pytest.fixture
def rail(vbus):
    with rail_on(vbus) as pair:
        yield pair


def test_rail_boots_moves_in_metres_and_holds_its_weight(rail):
    net, sim = rail
    net.boot()
    drive = sim.node("joint_1")
    assert [drive.get(od.FEED_CONSTANT, s) for s in (1, 2)] == [10_000, 1]       # written at bring-up (EDS: 5000)
    assert drive.get(od.POSITION_ENCODER_RESOLUTION, 1) == 10_000
    assert net.joints[0].k == pytest.approx(1.0e6)
    assert net.cycle().joint_positions[0] == 0.3                                 # brake on
    assert drive.get(od.POSITION_ACTUAL) == 300_000                              # um on the wire
    state = net.enable_all()
    # the brake lets go and the servo catches the slide (a sag of ~0.1 mm): inside the 5 mm window
    assert state.joint_positions[0] == pytest.approx(0.3, abs=0.005)
    goal = [0.55] + state.joint_positions[1:]
    state = net.move_to(goal, 3.0, settle_cycles=50)                             # 0.25 m, peak 0.13 m/s
    low, high, stiffness = rail_hold()
    step = 1.0e-6                                                                # encoder and wire increment
    droop = goal[0] - state.joint_positions[0]
    # PD servo: the drive holds the slide short of the target by force / stiffness (0.15..0.18 mm),
    # far inside the 5 mm following-error window, within one encoder step either way
    assert low / stiffness - step <= droop <= high / stiffness + step
    assert abs(droop) < 0.005
    assert sim.plant.joints[0].q == pytest.approx(state.joint_positions[0], abs=2 * step)   # the plant moved 0.25 m
    force = state.joints[0].torque
    assert low - RATED_FORCE / 1000 <= force <= high + RATED_FORCE / 1000        # pushes up the ramp (+q)
    assert state.joints[0].following_error == pytest.approx(droop, abs=2 * step)
    # the other joints are rotary as before
    assert net.joints[1].k == pytest.approx((1 << 20) * 100 / (2 * math.pi))


def test_a_rail_drive_with_read_only_scaling_reports_its_own_feed(vbus, tmp_path):
    """The compact drive model (read-only 608Fh/6091h/6092h: 2^17 increments, 160:1, its default
    5 mm lead) on the rail: the master uses what the drive reports, not the bus file's."""
    text = BUS.read_text().replace('device = "joint_drive"\nheartbeat_period = 0.1\n[nodes.joint]\n'
                                   'temperature_object = "0x2000"\nbrake_object = "0x2001"\nfeed_constant = 0.01',
                                   'device = "joint_drive"\nheartbeat_period = 0.1\neds = "joint_drive_compact.eds"\n'
                                   'pdo = { rpdo = [["0x6040", "0x607A"]], tpdo = [["0x6041", "0x6064", "0x6061"], '
                                   '["0x606C", "0x6077", "0x2000"]] }\n[nodes.joint]\nfeed_constant = 0.02', 1)
    assert "joint_drive_compact.eds" in text and "feed_constant = 0.02" in text
    path = tmp_path / "rail_compact.toml"
    path.write_text(text)
    with rail_on(vbus, path) as (net, sim):
        net.boot()
        assert "0x6092:01=5000" in net.bringup["joint_1"].read_only
        assert net.joints[0].k == pytest.approx((1 << 17) * 160 / 0.005)
        start = net.enable_all().joint_positions
        state = net.move_to([start[0] + 0.05] + start[1:], 1.0, settle_cycles=40)
        assert state.joint_positions[0] == pytest.approx(start[0] + 0.05, abs=0.5e-3)
        assert sim.plant.joints[0].q == pytest.approx(start[0] + 0.05, abs=0.5e-3)


def test_simulator_refuses_a_feed_constant_on_a_rotary_plant_joint(vbus):
    with pytest.raises(ConfigError, match="joint 1 is revolute in the plant but its drive node 1 'joint_1'.*has a feed_constant"):
        Simulator(vbus, load_bus_config(BUS), ROOT / "configs/plant/oru_testbed_nominal.toml")


def test_direct_path_scales_the_rail_as_the_can_path_does():
    from spacearm.offline.diagnosis.direct_sim import increments_per_unit, rated_joint_torque
    settings, params = load_bus_config(BUS).joints[0].joint, load_plant_config(PLANT).joint_params(0)
    assert increments_per_unit(settings, params) == pytest.approx(1.0e6)
    assert rated_joint_torque(settings, params) == pytest.approx(RATED_FORCE)
