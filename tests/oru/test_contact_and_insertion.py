"""The contact world and the contact subtasks on the plant without the bus (same controller
code as the task flow: spacearm.controller.oru.flow's ContactTask in an ImpedanceMode)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.base.config.scene import load_scene
from spacearm.firmware_sim.contact.cavity import Cavity, ContactLaw, MaleBox, box_in_cavity
from spacearm.offline.contact.trials import ContactTrials

LAW = ContactLaw(2.5e3, 0.0, 0.0, 1e-3)
SLOT = Cavity(0.0605, 0.0405, 0.010, 0.04)
ORU = MaleBox(0.06, 0.04, 0.10)


def pose(x=0.0, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def total(hit):
    return np.zeros(3) if hit is None else hit[1].sum(axis=0)


def test_chamfer_pushes_an_offset_part_toward_the_slot_centre_and_up():
    f = total(box_in_cavity(SLOT, ORU, LAW, pose(x=0.005, z=-0.008), np.zeros((4, 4))))
    assert f[0] < 0.0 and f[2] > 0.0 and f[0] == pytest.approx(-f[2], rel=1e-6)   # 45-degree normal


def test_centred_part_slides_freely_and_rests_on_the_floor():
    assert np.allclose(total(box_in_cavity(SLOT, ORU, LAW, pose(z=-0.02), np.zeros((4, 4)))), 0.0)
    f = total(box_in_cavity(SLOT, ORU, LAW, pose(z=-0.0402), np.zeros((4, 4))))
    assert f[2] == pytest.approx(4 * 2.5e3 * 0.0002) and abs(f[0]) < 1e-12   # four bottom corners


def test_no_contact_above_the_opening_or_beside_the_store():
    assert box_in_cavity(SLOT, ORU, LAW, pose(z=0.002), np.zeros((4, 4))) is None
    assert np.allclose(total(box_in_cavity(SLOT, ORU, LAW, pose(y=0.25, z=-0.01), np.zeros((4, 4)))), 0.0)


def skips_and_touches(rng, poses, cavity_of) -> tuple[int, int]:
    """(skipped, touching) of box_in_cavity over `poses` (index -> 4x4, drawn from rng) at a
    random rate: every pose it skips must be one the full computation finds free of force."""
    from spacearm.firmware_sim.contact.cavity import cavity_forces, sample_points
    law = ContactLaw(2.5e3, 30.0, 0.15, 1e-3)
    skipped = touching = 0
    for k, T in enumerate(poses):
        cavity = cavity_of(k)
        rate = np.zeros((4, 4))
        rate[:3, 3] = rng.normal(0.0, 0.01, 3)
        pm = sample_points(ORU, T, cavity.chamfer)
        full = cavity_forces(cavity, law, pm @ T[:3, :3].T + T[:3, 3], pm @ rate[:3, :3].T + rate[:3, 3])
        touching += bool(full.any())
        if box_in_cavity(cavity, ORU, law, T, rate) is None:
            skipped += 1
            assert not full.any(), f"pose {k}: skipped, but the full computation gives {full.sum(axis=0)} N"
    return skipped, touching


def test_the_quick_no_contact_test_never_hides_a_force():
    """box_in_cavity answers None without sampling when the box's corners show that nothing can
    touch; over poses around every surface (walls, chamfers, floor, rim, beside, above, tilted),
    each such None must be a pose the full computation also finds free of force."""
    from spacearm.base.spatial import rotvec_to_matrix
    rng = np.random.default_rng(5)
    closed = Cavity(SLOT.half_x, SLOT.half_y, SLOT.chamfer, 0.0)

    def poses():
        for k in range(3000):
            T = pose(*rng.uniform((-0.2, -0.15, -0.05), (0.2, 0.15, 0.02)))
            if k % 3:                                   # near the walls, where the decision is close
                T[0, 3] = rng.choice((-1, 1)) * (0.0005 + rng.normal(0.0, 0.001))
            T[:3, :3] = rotvec_to_matrix(rng.normal(0.0, 0.02, 3))
            yield T
    skipped, touching = skips_and_touches(rng, poses(), lambda k: closed if k % 4 == 0 else SLOT)
    assert skipped > 500 and touching > 500          # both kinds were really tried


def test_a_part_inserted_past_the_chamfer_is_skipped_only_when_it_touches_nothing():
    """Inserted deeper than the chamfer within about the clearance, the box's upper corners
    stand outside the wall's slab (above the opening) and its lower ones below the chamfer's
    funnel: the quick test then looks at the edges' part below the opening. Every pose it
    skips must be free of force in the full computation, and it must skip most of the free
    ones (the corners' hull alone skipped 487 of these 702: 69 %)."""
    from spacearm.base.spatial import rotvec_to_matrix
    rng = np.random.default_rng(11)
    clearance = SLOT.half_x - ORU.half_x

    def poses():
        for _ in range(2000):
            T = pose(rng.choice((-1, 1)) * rng.uniform(0.0, 2.5 * clearance), rng.normal(0.0, 0.3 * clearance),
                     rng.uniform(-SLOT.depth - 0.002, -SLOT.chamfer))
            T[:3, :3] = rotvec_to_matrix(rng.normal(0.0, 0.002, 3))
            yield T
    skipped, touching = skips_and_touches(rng, poses(), lambda k: SLOT)
    free = 2000 - touching
    assert touching > 200 and skipped > 0.85 * free, f"{skipped} of {free} free poses skipped"


def test_scene_geometry_places_a_captured_oru_in_its_slot():
    scene = load_scene()
    g = scene.geometry
    slot = scene.store("exposed").pose.matrix()
    tool = g.seated_tool_pose(slot)
    np.testing.assert_allclose(tool @ g.tool_T_oru(), slot @ g.slot_T_oru(), atol=1e-12)
    assert tool[2, 2] == pytest.approx(-1.0)         # tool points down into the slot


@pytest.fixture(scope="module")
def trials():
    return ContactTrials()


@pytest.mark.parametrize("lateral,angle_deg", [((0.008, 0.0), 0.0), ((0.0, -0.008), 0.0),
                                               ((0.004, 0.004), 1.5), ((-0.005, 0.002), -1.5)])
def test_insertion_corrected_by_the_chamfer_stops_at_F_tz(trials, lateral, angle_deg):
    r = trials.run("insert", "airlock_empty", lateral, (math.radians(angle_deg), 0.0, 0.0))
    assert r.success, r.failure
    assert r.final_lateral_error < 1.0e-3                 # inside the 0.5 mm slot clearance
    assert r.final_angle_error < math.radians(1.5)
    assert 2.5 < r.peak_insert_force < 20.0               # stopped once F_z exceeded F_tz


def test_capture_absorbs_open_loop_error_within_the_guide_tolerance(trials):
    r = trials.run("capture", "exposed", (0.008, -0.003))
    assert r.success, r.failure
    assert r.final_lateral_error < 1.0e-3


def test_capture_outside_the_guides_fails_with_a_reason(trials):
    r = trials.run("capture", "exposed", (-0.014, 0.0))       # beyond the 12 mm arc guide
    assert not r.success
    assert "jammed or blocked" in r.failure
