"""Trial kind `approach`: the changeout's closed-loop (visual servo) approach from a random start.

Runs bench/bench_vision.py's in-process stack (tests/vision/approach_stack.py, loaded from the
clone as the bench does): simulated nodes with the camera on the plant with geometry errors, the
daemon with its vision worker, lockstep clock, on a virtual bus of the trial's own. The arm is
moved open loop to the nominal pre-contact pose offset by the trial's start error, then the
approach runs; the figure is the final tool error against the *true* pre-contact pose.
The camera and the vision are in controller time (controller/vision/lockstep.py), but commands
enter the threaded daemon at a cycle that depends on wall time, so replays agree closely, not
to the bit (tests/vision/test_lockstep_camera.py steps the cycle itself and gets identical runs).
"""
from __future__ import annotations

import functools
import time
from typing import Any

import numpy as np

from spacearm.base.paths import REPO_ROOT
from spacearm.offline.campaign.kinds import TrialKind, TrialOutcome, in_clone, load_from_clone

STACK = REPO_ROOT / "tests" / "vision" / "approach_stack.py"
POSITION_LIMIT, ROTATION_LIMIT = 1e-3, np.radians(0.2)     # bench_vision's target


@functools.lru_cache(maxsize=1)
def _stack_class():
    return load_from_clone(STACK, "campaign_approach_stack").ApproachStack


def run_approach(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    from spacearm.base.spatial import xyz_rpy_to_transform

    in_clone()
    opts = {**APPROACH.options, **options}
    offset = xyz_rpy_to_transform([params.get(k, 0.0) for k in ("start_x", "start_y", "start_z")],
                                  [params.get(k, 0.0) for k in ("start_roll", "start_pitch", "start_yaw")])
    target, dz = str(opts["target"]), float(opts["dz"])
    stack = _stack_class()(opts["plant"])
    try:
        stack.enable()
        stack.move_joints_to(stack.nominal_goal(target, dz) @ offset)
        started = time.monotonic()
        result = stack.approach(target, dz, timeout=float(opts["timeout"]))
        wall = time.monotonic() - started
        if str(result["state"].value if hasattr(result["state"], "value") else result["state"]) != "enabled":
            return TrialOutcome(False, f"approach stopped: {result['stop_reason']}", {}, {"approach_wall_time": wall})
        T, goal = stack.sim.plant.tool_pose(), stack.true_goal(target, dz)
    finally:
        stack.close()
    position = float(np.linalg.norm(T[:3, 3] - goal[:3, 3]))
    rotation = float(np.arccos(np.clip((np.trace(goal[:3, :3].T @ T[:3, :3]) - 1) / 2, -1.0, 1.0)))
    ok = position <= POSITION_LIMIT and rotation <= ROTATION_LIMIT
    failure = None if ok else f"final error {1e3 * position:.2f} mm / {np.degrees(rotation):.3f} deg > 1 mm / 0.2 deg"
    return TrialOutcome(ok, failure, {"final_position_error": position, "final_rotation_error": rotation},
                        {"approach_wall_time": wall})


APPROACH = TrialKind(
    "approach", run_approach, ("start_x", "start_y", "start_z", "start_roll", "start_pitch", "start_yaw"),
    {"target": "exposed", "dz": 0.10, "plant": "configs/plant/oru_testbed_errors.toml", "timeout": 180.0},
    "final_position_error", "closed-loop visual-servo approach to the pre-contact pose from a random start",
    # replayed approaches end within a few hundredths of a mm of each other (measured 0.047 vs
    # 0.124 mm): a quarter of the success limits
    replay_atol={"final_position_error": 0.25e-3, "final_rotation_error": np.radians(0.05)})


# --- changeout_approach: bench_oru's randomised approaches, open vs closed loop on one draw ------------

@functools.lru_cache(maxsize=2)
def _approach_trials(plant: str, frame_every: int, latency_cycles: int):
    from spacearm.offline.scenarios.approach_trials import ApproachTrials
    return ApproachTrials(plant, frame_every=frame_every, latency_cycles=latency_cycles)


def _loop_figures(prefix: str, outcome) -> dict[str, float]:
    figures = {f"{prefix}_success": float(outcome.success)}
    if outcome.handover is not None:
        figures[f"{prefix}_handover_lateral"], figures[f"{prefix}_handover_angle"] = (float(v) for v in outcome.handover)
    if outcome.contact is not None:
        figures[f"{prefix}_peak_insert_force"] = float(outcome.contact.peak_insert_force)
    return figures


def _loop_failure(outcome) -> str | None:
    if outcome.success:
        return None
    return outcome.failure or (outcome.contact.failure if outcome.contact is not None else None) or "not seated"


def run_changeout_approach(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    """One draw of a store placement error (parameters placement_*) for one of the changeout's
    four approaches (level `stage`: its (store, placing) in flow order), flown both ways on the
    same draw: open loop (nominal model's joints) and closed loop (approach mode on rendered
    frames). Success is the closed loop's; the open loop's outcome is in the open_* figures.
    Both loops run in one trial: draws come from the trial's own seed, so a level would pair
    different draws."""
    in_clone()
    from spacearm.controller.oru.config import load_changeout
    from spacearm.offline.scenarios.approach_trials import Placement

    opts = {**CHANGEOUT_APPROACH.options, **options}
    stages = [(s.store, i % 2 == 1) for i, s in enumerate(load_changeout().stages)]
    store, placing = stages[int(params.get("stage", 0)) % len(stages)]
    placement = Placement(tuple(params.get(f"placement_{k}", 0.0) for k in ("x", "y", "z")),
                          tuple(params.get(f"placement_{k}", 0.0) for k in ("roll", "pitch", "yaw")))
    trials = _approach_trials(opts["plant"], int(opts["frame_every"]), int(opts["latency_cycles"]))
    trials.camera.rng = np.random.default_rng(seed)       # the camera noise of this trial alone
    open_loop = trials.open_loop(store, placing, placement)
    closed = trials.closed_loop(store, placing, placement, int(opts["max_cycles"]))
    figures = {**_loop_figures("closed", closed), **_loop_figures("open", open_loop)}
    labels = {"store": store, "subtask": "insert" if placing else "capture"}
    if not open_loop.success:
        labels["open_failure"] = _loop_failure(open_loop)
    return TrialOutcome(closed.success, _loop_failure(closed), figures,
                        {"closed_wall_time": closed.wall_time, "open_wall_time": open_loop.wall_time}, labels=labels)


CHANGEOUT_APPROACH = TrialKind(
    "changeout_approach", run_changeout_approach,
    ("stage", "placement_x", "placement_y", "placement_z", "placement_roll", "placement_pitch", "placement_yaw"),
    {"plant": "configs/plant/oru_cell_errors.toml", "frame_every": 3, "latency_cycles": 3, "max_cycles": 2000},
    "closed_handover_lateral",
    "changeout approach from a random store placement, open loop vs closed loop (vision) on the same draw, "
    "then the contact subtask")
