"""The concealed-effect benchmark end to end on a few short cases (the CI-sized run)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "bench" / "bench_diagnosis.py"


def test_small_benchmark_generates_scores_and_keeps_truth_apart(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("bench_diagnosis", BENCH)
    bench = importlib.util.module_from_spec(spec)
    sys.modules["bench_diagnosis"] = bench        # dataclasses look their module up there
    spec.loader.exec_module(bench)
    out = bench.main(["--cases", "5", "--duration", "20", "--seed", "3", "--no-timing", "--keep", str(tmp_path)])
    printed = capsys.readouterr().out
    assert "named 1st" in printed and "false alarm" in printed
    scores = out["scores"]
    assert len(scores) == 5 and {s["kind"] for s in scores} == {"one", "two", "none"}
    # the recordings directory holds no truth: the tool's inputs are the CSVs alone
    assert sorted(p.suffix for p in (tmp_path / "recordings").iterdir()) == [".csv"] * 5
    assert len(list((tmp_path / "truth").glob("*.json"))) == 5
    null = [s for s in scores if s["kind"] == "none"]
    assert not any(s["false_alarm"] for s in null)
    visible = [s for s in scores if s["visible"]]
    assert sum(s["named"] for s in visible) >= len(visible) - 1
