"""Real-time scheduling requests: granted where permitted, a clear reason where not, and
never inherited by work that must stay at normal priority."""
from __future__ import annotations

import os
import threading

import pytest

from spacearm.base.runtime.priority import describe, use_fifo, use_normal


def _in_thread(fn):
    out = []
    t = threading.Thread(target=lambda: out.append(fn()))
    t.start()
    t.join()
    return out[0]


def test_priority_zero_is_not_a_request_and_out_of_range_is_refused():
    assert use_fifo(0) == "not requested"
    for bad in (-1, 100):
        with pytest.raises(ValueError, match="1..99"):
            use_fifo(bad)


def test_fifo_is_granted_or_explained_and_inherited_by_new_threads_until_use_normal():
    def body():
        problem = use_fifo(10)
        if problem is not None:
            # no CAP_SYS_NICE here: the reason names the policy and the thread runs on normally
            assert "SCHED_FIFO not permitted" in problem and describe() == "normal"
            return "skipped"
        assert describe() == "SCHED_FIFO 10"
        child = _in_thread(describe)                       # threads inherit their creator's policy
        lowered = _in_thread(lambda: (use_normal(), describe())[1])
        use_normal()
        return child, lowered, describe()

    result = _in_thread(body)          # in a thread of its own: the test runner's thread stays normal
    if result == "skipped":
        pytest.skip("SCHED_FIFO not permitted on this machine")
    assert result == ("SCHED_FIFO 10", "normal", "normal")
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
