"""Fuzzing with hypothesis: a bounded number of cases per test (fast in CI), more with
SPACEARM_FUZZ_EXAMPLES=N (bench/bench_reliability.py uses it and counts the cases run)."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from hypothesis import HealthCheck, settings

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

EXAMPLES = int(os.environ.get("SPACEARM_FUZZ_EXAMPLES", "300"))
settings.register_profile("fuzz", max_examples=EXAMPLES, deadline=None, derandomize=False,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])
settings.load_profile("fuzz")


class CaseCounter:
    """Counts the cases each fuzz test ran (written to SPACEARM_FUZZ_COUNTS for the bench)."""
    counts: dict[str, int] = {}

    @classmethod
    def hit(cls, name: str) -> None:
        cls.counts[name] = cls.counts.get(name, 0) + 1


def pytest_sessionfinish(session, exitstatus):
    path = os.environ.get("SPACEARM_FUZZ_COUNTS")
    # the tests import this file as tests.fuzz.conftest, pytest may load it under another name
    imported = sys.modules.get("tests.fuzz.conftest")
    counts = dict(CaseCounter.counts)
    if imported is not None and imported.CaseCounter is not CaseCounter:
        for name, n in imported.CaseCounter.counts.items():
            counts[name] = counts.get(name, 0) + n
    if path and counts:
        import json
        with open(path, "w") as f:
            json.dump(counts, f)
