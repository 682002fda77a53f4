"""The simulated drive's CiA 402 transitions against the python-canopen library's own table
(canopen.profiles.p402.State402.TRANSITIONTABLE: for each (from, to) the controlword a master
sends), which nobody on the team wrote, for every quick stop option code 605Ah may hold."""
from __future__ import annotations

import itertools

import pytest
from canopen.profiles.p402 import State402

from spacearm.base.canopen.cia402_defs import Command, State, decode_controlword
from spacearm.firmware_sim.cia402_state_machine import next_state

# the states a controlword moves the drive between (the rest come from the drive itself:
# 0/1 at power-on, 13-15 on a fault)
COMMANDED = {State.SWITCH_ON_DISABLED, State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED,
             State.QUICK_STOP_ACTIVE}
OPTIONS = range(0, 9)      # 605Ah


def _library_transitions():
    names = {s.value for s in COMMANDED}
    for (start, end), cw in State402.TRANSITIONTABLE.items():
        if start in names and end in names:
            yield State(start), State(end), cw


LIBRARY = list(_library_transitions())


def test_the_library_table_covers_the_commanded_transitions():
    assert len(LIBRARY) == 12        # 2-12 and 16 (the 3 + 4 shortcut is not one of its rows)


@pytest.mark.parametrize(("start", "end", "cw"), LIBRARY, ids=[f"{s.value}->{e.value}" for s, e, _ in LIBRARY])
@pytest.mark.parametrize("option", OPTIONS)
def test_each_library_controlword_leads_where_the_library_says(start, end, cw, option):
    got = next_state(start, decode_controlword(cw), option)
    if start is State.OPERATION_ENABLED and end is State.QUICK_STOP_ACTIVE and option == 0:
        assert got is State.SWITCH_ON_DISABLED     # 605Ah 0: the drive function is disabled at once
    elif start is State.QUICK_STOP_ACTIVE and end is State.OPERATION_ENABLED and option not in (5, 6, 7, 8):
        assert got is State.QUICK_STOP_ACTIVE      # 16 only from a quick stop that stays (605Ah 5-8)
    else:
        assert got is end


def test_no_command_leads_anywhere_the_library_has_no_transition_to():
    """Every (state, command) pair: either a library transition, the 3 + 4 shortcut, the quick
    stop command that disables voltage too (7, 10), or no change."""
    allowed = {(s, e) for s, e, _ in LIBRARY} | {(State.READY_TO_SWITCH_ON, State.OPERATION_ENABLED),
                                               (State.OPERATION_ENABLED, State.SWITCH_ON_DISABLED)}
    for start, command, option in itertools.product(COMMANDED, Command, OPTIONS):
        got = next_state(start, command, option)
        assert got is start or (start, got) in allowed, (start, command, option, got)
