"""Trial kind `diagnosis`: one concealed-effect case of bench/bench_diagnosis.py per trial.

The trial calls the benchmark's per-case entry point `run_case(effects, seed, duration, work,
name)` (the script is loaded from the clone, as tests/diagnosis does): generate one hidden plant
+ trajectory + noisy recording from the seed, diagnose the recording alone, score against the
truth. `effects` (0, 1 or 2 hidden effects) is the case type; the benchmark's mix is the
campaign's `[levels.effects] values = [1, 1, 1, 2, 0]`. The bench prints its table from the rows.
"""
from __future__ import annotations

import functools
import tempfile
from pathlib import Path
from typing import Any

from spacearm.base.paths import REPO_ROOT
from spacearm.offline.campaign.kinds import TrialKind, TrialOutcome, in_clone, load_from_clone

BENCH = REPO_ROOT / "bench" / "bench_diagnosis.py"


@functools.lru_cache(maxsize=1)
def _bench():
    return load_from_clone(BENCH, "bench_diagnosis")


def run_diagnosis_case(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    in_clone()
    opts = {**DIAGNOSIS.options, **options}
    effects = params.get("effects", 1.0)
    if effects not in (0.0, 1.0, 2.0):
        raise ValueError(f"parameter effects: expected 0, 1 or 2 hidden effects, got {effects!r}")
    name = f"case{seed}"
    if opts["keep"]:             # the bench's --keep: recordings, truths and reports side by side
        score, times = _bench().run_case(int(effects), seed, float(opts["duration"]), Path(opts["keep"]), name)
    else:
        with tempfile.TemporaryDirectory(prefix="campaign_diag_") as tmp:
            score, times = _bench().run_case(int(effects), seed, float(opts["duration"]), Path(tmp), name)
    return case_outcome(score, times)


def case_outcome(score, times: dict[str, float]) -> TrialOutcome:
    """A bench_diagnosis Score as a trial: success = named first (no alarm on a case without effect)."""
    figures = {"effects": float(len(score.effects)), "visible": float(score.visible),
               "named_first": float(score.named), "false_alarm": float(score.false_alarm)}
    if score.param_ok:               # only where the effect was found and has a fitted parameter
        figures["parameter_within_15pct"] = float(all(score.param_ok))
    if score.rms_reduction:
        figures["rms_reduction"] = float(min(score.rms_reduction))
    if score.kind == "none":
        failure = "false alarm" if score.false_alarm else None
    else:
        effects = ", ".join(score.effects)
        failure = None if score.named else f"{effects} not named first ({score.why or score.answer})"
    series = {"param_ok": [float(p) for p in score.param_ok], "rms_reduction": list(score.rms_reduction)}
    labels = {"case_type": score.kind, "effect_names": ",".join(score.effects), "answer": score.answer,
              "why": score.why}
    return TrialOutcome(bool(score.named), failure, figures, dict(times), series, labels)


DIAGNOSIS = TrialKind(
    "diagnosis", run_diagnosis_case, ("effects",), {"duration": 20.0, "keep": ""}, "false_alarm",
    "sim-vs-real diagnosis on one concealed-effect case of bench_diagnosis (generator, tool, scorer)")
