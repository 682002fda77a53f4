"""URDF import: the arm file's FK agrees with Pinocchio's reading of the same URDF, limits
carry over, fixed joints fold, parallel axes get Hayati beta, and bad URDFs give one clear error."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.kinematics import KinematicData, KinematicModel, fk, jacobian
from spacearm.base.kinematics.arm_import import arm_toml, import_arm
from spacearm.base.kinematics.urdf import UrdfError
from tests.kinematics.urdf_reference import REPO, URDFS, PinocchioChain


@pytest.fixture(scope="module", params=sorted(URDFS))
def imported(request):
    urdf, base, tip = URDFS[request.param]
    _, config = import_arm(urdf, base, tip)
    model = KinematicModel.from_config(config)
    return request.param, config, model, PinocchioChain(urdf, base, tip, [j.name for j in config.joints])


def test_fk_of_imported_arm_agrees_with_pinocchio(imported) -> None:
    _, _, model, ref = imported
    data = KinematicData(model)
    for q in model.random_configurations(100, np.random.default_rng(3)):
        ours, theirs = fk(model, data, q), ref.tip_in_base(q)
        assert np.abs(ours[:3, 3] - theirs[:3, 3]).max() < 1e-9          # m
        assert np.abs(ours[:3, :3] - theirs[:3, :3]).max() < 1e-9        # rad (small-angle)


def test_jacobian_of_imported_arm_agrees_with_pinocchio(imported) -> None:
    _, _, model, ref = imported
    data = KinematicData(model)
    for q in model.random_configurations(10, np.random.default_rng(4)):
        pq = ref.q(q)
        J = pin.computeFrameJacobian(ref.model, ref.data, pq, ref.tip, pin.LOCAL_WORLD_ALIGNED)
        v = [ref.model.joints[ref.model.getJointId(n)].idx_v for n in ref.names]
        # both in the base frame (the URDF base link is Pinocchio's universe here)
        assert np.abs(jacobian(model, data, q) - J[:, v]).max() < 1e-9


def test_tiago_torso_is_prismatic_with_its_urdf_limits(imported) -> None:
    name, config, model, _ = imported
    if name != "tiago":
        pytest.skip("TIAGo only")
    torso = config.joints[0]
    assert torso.name == "torso_lift_joint" and torso.type == "prismatic"
    assert (torso.limits.lower, torso.limits.upper) == (0.0, 0.35)
    assert torso.drive.velocity == 0.07 and torso.drive.torque == 2000.0
    assert model.nq == 8 and model.joint_types[1:] == ("revolute",) * 7


def test_ur10_parallel_axes_get_hayati_beta_and_limits(imported) -> None:
    name, config, _, _ = imported
    if name != "ur10":
        pytest.skip("UR10 only")
    betas = [j.beta is not None for j in config.joints]
    assert betas == [False, False, True, True, False, False]   # joints 2, 3, 4 share parallel axes
    assert config.joints[0].limits.lower == pytest.approx(-2 * np.pi)
    assert config.joints[0].drive.torque == 330.0


def test_fixed_joints_fold_into_base_and_tool(imported) -> None:
    name, config, model, ref = imported
    urdf, base, tip = URDFS[name]
    assert len(config.joints) == len(ref.names)     # only moving joints became rows
    assert config.urdf is not None and config.urdf.tip == tip
    assert len(config.links) == model.nq


def test_written_arm_file_reads_back_with_the_same_fk(tmp_path) -> None:
    urdf, base, tip = URDFS["panda"]
    data, config = import_arm(urdf, base, tip, tmp_path / "panda.toml")
    (tmp_path / "panda.toml").write_text(arm_toml(data, "test"))
    again = KinematicModel.from_config(load_arm_config(tmp_path / "panda.toml"))
    model = KinematicModel.from_config(config)
    q = model.random_configurations(1, np.random.default_rng(5))[0]
    assert np.array_equal(fk(again, KinematicData(again), q), fk(model, KinematicData(model), q))


ROBOT = """<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="{kind}"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>{limit}</joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.3 0 0"/>
    <limit lower="-1" upper="1" velocity="1" effort="10"/></joint>
</robot>"""


@pytest.mark.parametrize("kind, limit, tip, expected", [
    ("floating", "", "c", "joint 'j1' is floating"),
    ("planar", "", "c", "joint 'j1' is planar"),
    ("screw", "", "c", "unknown joint type 'screw'"),
    ("prismatic", "", "c", "prismatic joint 'j1' has no <limit"),
    ("revolute", '<limit lower="-1" upper="1" velocity="1" effort="1"/>', "nowhere", "tip link 'nowhere' is not"),
])
def test_bad_urdf_names_the_joint_or_link(tmp_path, kind, limit, tip, expected) -> None:
    path = tmp_path / "r.urdf"
    path.write_text(ROBOT.format(kind=kind, limit=limit))
    with pytest.raises(UrdfError, match=expected) as info:
        import_arm(path, "a", tip)
    assert str(path) in str(info.value)


def test_chain_that_does_not_connect_is_refused(tmp_path) -> None:
    path = tmp_path / "r.urdf"
    path.write_text(ROBOT.format(kind="revolute", limit='<limit lower="-1" upper="1" velocity="1" effort="1"/>'))
    with pytest.raises(UrdfError, match="link 'a' is not connected to base 'c'"):
        import_arm(path, "c", "a")


def test_unparsable_urdf_is_one_line_from_the_command(tmp_path) -> None:
    path = tmp_path / "broken.urdf"
    path.write_text("<robot><link name='a'>")
    out = subprocess.run([sys.executable, "-m", "spacearm.console.main", "arm", "import", str(path), "--base", "a",
                          "--tip", "b"], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and "not valid XML" in out.stderr and str(path) in out.stderr
    assert "Traceback" not in out.stderr


def test_command_writes_arm_bus_and_plant_files(tmp_path) -> None:
    urdf, base, tip = URDFS["tiago"]
    arm, bus, plant = tmp_path / "tiago.toml", tmp_path / "bus.toml", tmp_path / "plant.toml"
    out = subprocess.run([sys.executable, "-m", "spacearm.console.main", "arm", "import", str(urdf), "--base", base,
                          "--tip", tip, "--out", str(arm), "--bus", str(bus), "--plant", str(plant),
                          "--gravity", "9.81"], capture_output=True, text=True, cwd=REPO)
    assert out.returncode == 0, out.stderr
    assert "8 joints (prismatic, revolute" in out.stdout
    from spacearm.base.config.bus import load_bus_config
    from spacearm.firmware_sim.plant import load_plant_config
    assert [n.name for n in load_bus_config(bus).joints] == [f"joint_{i}" for i in range(1, 9)]
    assert load_plant_config(plant).rigid_body.gravity == (0.0, 0.0, -9.81)


def test_missing_inertials_are_named_and_refused_for_a_plant(tmp_path) -> None:
    """ROBOT's links have no <inertial>: the import says which, and a plant (rigid-body dynamics) is refused."""
    path = tmp_path / "r.urdf"
    path.write_text(ROBOT.format(kind="revolute", limit='<limit lower="-1" upper="1" velocity="1" effort="1"/>'))
    run = lambda *extra: subprocess.run([sys.executable, "-m", "spacearm.console.main", "arm", "import", str(path),
                                         "--base", "a", "--tip", "c", "--out", str(tmp_path / "r.toml"), *extra],
                                        capture_output=True, text=True, cwd=REPO)
    out = run()
    assert out.returncode == 0 and "no <inertial> on link 'b' (joint 'j1'), link 'c' (joint 'j2')" in out.stdout
    refused = run("--plant", str(tmp_path / "p.toml"))
    assert refused.returncode == 2 and "error[bad_input]" in refused.stderr and refused.stderr.count("\n") == 1 and "link 'b' (joint 'j1')" in refused.stderr
    assert not (tmp_path / "p.toml").exists()
