"""The insertion trial gives, bit for bit, the figures of the code it was sped up from.

Issue 35 asks for more insertion trials per minute with the same results for the same seeds.
The expected figures below were computed by the issue's reference tree 9e80b96 (`float.hex`,
so every bit counts): two trials of configs/campaigns/insertion_smoke.toml (its own draws) and
one capture at the exposed store (the adapter in the end effector's guides)."""
from __future__ import annotations

import pytest

from spacearm.offline.campaign.kinds import run_insertion
from spacearm.offline.campaign.schema import load_campaign

pytestmark = pytest.mark.slow

SMOKE = "configs/campaigns/insertion_smoke.toml"
CAPTURE = ({"lateral_radius": 0.005, "lateral_phase": 2.0, "tilt_angle": 0.01, "tilt_axis": 0.5},
           {"subtask": "capture", "store": "exposed", "max_cycles": 1500})
EXPECTED = {
    "smoke trial 0": {"peak_lateral_force": "0x1.4b985479f48a7p+1", "peak_torque": "0x1.6f3bf3b7bbf92p-3",
                      "peak_insert_force": "0x1.78ec54d85847ep+2", "arm_time": "0x1.6c28f5c28f56cp+3",
                      "final_lateral_error": "0x1.42fa1c100243bp-11", "final_angle_error": "0x1.9a9378477ea61p-10"},
    "smoke trial 3": {"peak_lateral_force": "0x1.70314011788f3p+1", "peak_torque": "0x1.992a4b8e6957cp-3",
                      "peak_insert_force": "0x1.7e91e453e8817p+2", "arm_time": "0x1.67ae147ae1426p+3",
                      "final_lateral_error": "0x1.091230c973d74p-11", "final_angle_error": "0x1.24f4d902eaa40p-7"},
    "capture": {"peak_lateral_force": "0x1.8b6497683f935p+1", "peak_torque": "0x1.c80023acf07c8p-5",
                "peak_insert_force": "0x1.0f5dc3942e34ep+2", "arm_time": "0x1.03d70a3d70a0ep+3",
                "final_lateral_error": "0x1.108602ed54179p-11", "final_angle_error": "0x1.34a6c3e78e6dcp-7"},
}


def case(name: str) -> tuple[dict, dict]:
    if name == "capture":
        return CAPTURE
    campaign = load_campaign(SMOKE)
    return campaign.parameters(int(name.rsplit(" ", 1)[1])), dict(campaign.spec.options)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_trial_gives_the_reference_trees_figures_bit_for_bit(name):
    params, options = case(name)
    outcome = run_insertion(params, options, 0)
    assert outcome.success and outcome.failure is None
    got = {k: float(v).hex() for k, v in outcome.figures.items()}
    assert got == EXPECTED[name], f"{name}: figures differ from 9e80b96's: {got}"
