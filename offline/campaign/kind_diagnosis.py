"""Trial kind `diagnosis`: one concealed-effect case of bench/bench_diagnosis.py per trial.

The case generator, the scorer and the diagnosis are the benchmark's own functions (the script
is loaded from the clone, as tests/diagnosis does), called with the trial's seed: generate one
hidden plant + trajectory + noisy recording, diagnose the recording alone, score against the
truth. The bench's generator draws the case type from the case's position in its loop, so a
single-case trial is always a one-effect case (effect type, joint and size random).
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
    import json

    from spacearm.firmware_sim.plant import load_plant_config
    from spacearm.offline.diagnosis.analysis import diagnose
    from spacearm.offline.diagnosis.recording_io import read_table
    from spacearm.offline.diagnosis.report import write_report

    in_clone()
    bench = _bench()
    opts = {**DIAGNOSIS.options, **options}
    with tempfile.TemporaryDirectory(prefix="campaign_diag_") as tmp:
        rec, truth_dir, rep = (Path(tmp) / d for d in ("recordings", "truth", "report"))
        for d in (rec, truth_dir, rep):
            d.mkdir()
        # the bench multiplies its seed for the noise streams: keep it in numpy's int64 range
        (path,) = bench.generate(1, float(opts["duration"]), seed % 2 ** 31, rec, truth_dir)
        nominal = load_plant_config(bench.NOMINAL)
        summary = write_report(diagnose(read_table(path), nominal), rep, path.name, nominal)
        truth = json.loads((truth_dir / f"{path.stem}.json").read_text())
    score = bench.score_case(summary, truth)
    visibility = min((t["visibility"] for t in truth["truths"]), default=0.0)
    figures = {"visibility": float(visibility), "named_first": float(score.named),
               "false_alarm": float(score.false_alarm)}
    if score.param_ok:               # only where the effect was found and has a fitted parameter
        figures["parameter_within_15pct"] = float(all(score.param_ok))
    if score.rms_reduction:
        figures["rms_reduction"] = float(min(score.rms_reduction))
    effects = ", ".join(score.effects) or "none"
    failure = None if score.named else f"{effects} not named first ({score.why or score.answer})"
    return TrialOutcome(bool(score.named), failure, figures)


DIAGNOSIS = TrialKind(
    "diagnosis", run_diagnosis_case, (), {"duration": 20.0}, "false_alarm",
    "sim-vs-real diagnosis on one concealed-effect case of bench_diagnosis (generator, tool, scorer)")
