"""The status text: a daemon's first status does not call its cycle statistics an error."""
from __future__ import annotations

from spacearm.console.status_view import STATS_SETTLED, status_lines


def _status(cycles: int, level: str) -> dict:
    stats = dict(period_error_median=0.0, period_error_p99=0.0, period_error_max=0.0, execution_p99=0.012,
                 compute_p99=0.001, overruns=0, level=level, cycles=cycles)
    return {"state": "disabled", "stats": stats}


def test_the_first_cycles_say_starting_not_error():
    line = next(x for x in status_lines(_status(1, "error")) if x.startswith("cycle:"))
    assert "overruns 0 [starting]" in line and "[error]" not in line


def test_settled_statistics_show_their_level():
    line = next(x for x in status_lines(_status(STATS_SETTLED, "error")) if x.startswith("cycle:"))
    assert "overruns 0 [error]" in line


def test_overruns_are_shown_with_their_measured_causes():
    status = _status(STATS_SETTLED, "warn")
    status["stats"] |= {"overruns": 3, "overrun_causes": {"host": 2, "gil": 1}}
    line = next(x for x in status_lines(status) if x.startswith("cycle:"))
    assert "overruns 3; by cause: host 2, gil 1 [warn]" in line
