"""Trial kinds: what one trial of a campaign runs, as a function of (parameters, options, seed).

Each kind calls the same trial functions the benchmarks and studies use (bench/bench_oru.py's
ContactTrials.run, one run of a calibration study in controller/calibration/study_trials,
bench_diagnosis's run_case, the checkout scenario), so a campaign and a benchmark measure the
same thing. A trial returns a TrialOutcome; an exception is not a failed trial but a broken one
(the runner retries it, then records it as an error).
"""
from __future__ import annotations

import functools
import math
import os
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from spacearm.base.paths import REPO_ROOT


@dataclass
class TrialOutcome:
    success: bool
    failure: str | None                    # why it failed (None when it succeeded)
    figures: dict[str, float] = field(default_factory=dict)   # deterministic given the seed
    timings: dict[str, float] = field(default_factory=dict)   # wall-clock figures: never compared
    series: dict[str, list[float]] = field(default_factory=dict)   # arrays a study pools (deterministic)
    labels: dict[str, str] = field(default_factory=dict)      # words a benchmark's table groups by


@dataclass(frozen=True)
class TrialKind:
    name: str
    run: Callable[[dict[str, float], dict[str, Any], int], TrialOutcome]
    parameters: tuple[str, ...]            # what a campaign file may draw
    options: dict[str, Any]                # fixed options and their defaults
    worst: str                             # figure whose largest values are the worst trials
    doc: str = ""
    # replay compares figures to rounding (kinds that are a pure function of the seed), or to
    # these absolute tolerances (SI) where thread timing enters (CHECKOUT, APPROACH)
    replay_atol: dict[str, float] = field(default_factory=dict)


def in_clone() -> None:
    """Configuration files are data in the clone (spacearm.base.paths), named relative to it; a
    worker started elsewhere (another host's `dask worker`) runs trials from the clone's root.
    Workers run one trial at a time (one thread), so the working directory is theirs alone."""
    if os.getcwd() != str(REPO_ROOT):
        os.chdir(REPO_ROOT)


def load_from_clone(path, module_name: str):
    """A benchmark's or test's own module that is not part of the package (bench/, tests/),
    loaded from the clone by path: campaigns call the very code those benches loop over."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module       # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


# --- insertion / capture: the contact subtasks of bench_oru (no bus, DirectLoop) -----------------

@functools.lru_cache(maxsize=4)
def _contact_trials(plant: str):
    from spacearm.offline.contact.trials import ContactTrials
    return ContactTrials(plant)


def run_insertion(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    in_clone()
    from spacearm.offline.contact.trials import PLANT
    opts = {**INSERTION.options, **options}
    if opts["subtask"] not in ("insert", "capture"):
        raise ValueError(f"options.subtask: expected insert or capture, got {opts['subtask']!r}")
    trials = _contact_trials(opts["plant"] or PLANT)
    r, phi = params.get("lateral_radius", 0.0), params.get("lateral_phase", 0.0)
    angle, axis = params.get("tilt_angle", 0.0), params.get("tilt_axis", 0.0)
    lateral = (r * math.cos(phi), r * math.sin(phi))
    rotvec = (angle * math.cos(axis), angle * math.sin(axis), 0.0)   # tilt about a horizontal axis
    res = trials.run(opts["subtask"], opts["store"], lateral, rotvec, opts["oru"], int(opts["max_cycles"]))
    figures = {"peak_lateral_force": res.peak_lateral_force, "peak_torque": res.peak_torque,
               "peak_insert_force": res.peak_insert_force, "arm_time": res.arm_time,
               "final_lateral_error": res.final_lateral_error, "final_angle_error": res.final_angle_error}
    failure = None if res.success else (res.failure or "not seated")
    return TrialOutcome(res.success, failure, figures, {"trial_wall_time": res.wall_time})


INSERTION = TrialKind(
    "insertion", run_insertion, ("lateral_radius", "lateral_phase", "tilt_axis", "tilt_angle"),
    {"subtask": "insert", "store": "airlock_empty", "oru": "old_oru", "max_cycles": 3000, "plant": ""},
    "peak_lateral_force", "ORU insertion (or capture) from a random start error, plant + impedance mode")


# --- checkout soak: simulator + daemon in lockstep on a bus of the trial's own ----------------------

def run_checkout_trial(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    """The functional checkout over CAN: simulated nodes and the daemon in this process, lockstep
    clock, on a virtual bus named after the process and the seed (unique, so trials run side by side)."""
    in_clone()
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    from spacearm.firmware_sim.runner import start_simulator
    from spacearm.offline.scenarios.checkout import CheckoutFailed, run_checkout

    opts = {**CHECKOUT.options, **options}
    bus = f"virtual:campaign-{os.getpid()}-{threading.get_ident()}-{seed}-{time.monotonic_ns()}"
    sim = start_simulator(bus, opts["bus_config"], opts["plant"], time_base="sync")
    daemon = Daemon(DaemonOptions(bus=bus, arm=opts["arm"], bus_config=opts["bus_config"], clock="lockstep",
                                  api=None, record_dir=None, gil_switch_interval=None))
    started = time.perf_counter()
    try:
        daemon.start()
        cycle = threading.Thread(target=daemon.run, name="campaign-cycle", daemon=True)
        cycle.start()
        try:
            result = run_checkout(daemon, lambda i, name, frac: None)
        except CheckoutFailed as exc:
            return TrialOutcome(False, str(exc), {}, {"trial_wall_time": time.perf_counter() - started})
        finally:
            daemon.request_stop()
            cycle.join(10)
    finally:
        daemon.request_stop()
        daemon.shutdown()
        sim.stop()
    steps = result.steps
    finals = [s.final_position_error for s in steps if s.final_position_error is not None]
    figures = {"max_tracking_error": max(s.max_tracking_error for s in steps)}
    if finals:
        figures["final_position_error"] = max(finals)
    # arm time and cycles count when the scenario thread's commands land in the cycle: timing
    return TrialOutcome(True, None, figures, {"trial_wall_time": time.perf_counter() - started,
                                              "arm_time": sum(s.duration for s in steps),
                                              "cycles": float(result.cycles)})


CHECKOUT = TrialKind(
    "checkout", run_checkout_trial, (),
    # slower heartbeats (0.25 s, loss after 0.625 s): trials run side by side on a loaded machine, and a node thread
    # starved for 0.25 s is the machine's load, not the bus under test
    {"arm": "configs/arm/oru_testbed_6dof.toml", "bus_config": "configs/oru/bus_shared_machine.toml",
     "plant": "configs/plant/oru_testbed_nominal.toml"},
    "max_tracking_error", "soak: the functional checkout over CAN, simulator + daemon in lockstep",
    # not bit-reproducible: the scenario (a thread) sends each command on whichever cycle is
    # current, so the step boundaries move by a few cycles between runs (measured: final
    # position error 62-69 um, tracking error 0.666-0.676 mrad)
    replay_atol={"final_position_error": 20e-6, "max_tracking_error": 50e-6})


# kinds that load a benchmark's own stack from the clone live in modules of their own
from spacearm.offline.campaign.kind_approach import APPROACH, CHANGEOUT_APPROACH  # noqa: E402
from spacearm.offline.campaign.kind_calibration import CALIBRATION_EKF, CALIBRATION_LASER, CALIBRATION_MODEL  # noqa: E402
from spacearm.offline.campaign.kind_diagnosis import DIAGNOSIS  # noqa: E402

KINDS: dict[str, TrialKind] = {k.name: k for k in (INSERTION, CALIBRATION_LASER, CALIBRATION_EKF, CALIBRATION_MODEL,
                                                   CHECKOUT, DIAGNOSIS, APPROACH, CHANGEOUT_APPROACH)}
