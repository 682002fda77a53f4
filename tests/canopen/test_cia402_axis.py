"""Controller-side CiA 402 state machine driver, without a bus."""
from __future__ import annotations

from spacearm.drivers.cia402 import FAULT_RESET_VERIFY_CYCLES, Cia402Axis
from spacearm.base.canopen.cia402_defs import STATE_BITS, State, decode_statusword


def sw(state: State, extra: int = 0) -> int:
    return STATE_BITS[state] | extra


def test_decode_every_state_with_noise_bits():
    for state, bits in STATE_BITS.items():
        assert decode_statusword(bits | 0x0200 | 0x0400) == state


def test_enable_one_transition_per_step():
    a = Cia402Axis()
    a.enable()
    assert a.step(sw(State.SWITCH_ON_DISABLED)) == 0x06
    assert a.step(sw(State.READY_TO_SWITCH_ON)) == 0x07
    assert a.step(sw(State.SWITCHED_ON)) == 0x0F
    assert a.step(sw(State.OPERATION_ENABLED)) == 0x0F
    assert a.enabled


def test_quick_stop_and_disable():
    a = Cia402Axis()
    a.enable()
    a.step(sw(State.OPERATION_ENABLED))
    a.quick_stop()
    assert a.step(sw(State.OPERATION_ENABLED)) == 0x02
    assert a.step(sw(State.QUICK_STOP_ACTIVE)) == 0x02
    a.disable()
    assert a.step(sw(State.QUICK_STOP_ACTIVE)) == 0x00


def test_fault_waits_for_explicit_reset_then_verifies():
    a = Cia402Axis()
    a.enable()
    assert a.step(sw(State.FAULT)) == 0x00          # no automatic reset
    a.fault_reset()
    assert a.step(sw(State.FAULT)) == 0x00          # bit 7 low
    assert a.step(sw(State.FAULT)) == 0x80          # rising edge
    assert a.step(sw(State.SWITCH_ON_DISABLED)) == 0x06   # cleared -> continues enabling
    assert a.fault_cleared and not a.fault_reset_failed


def test_fault_reset_that_does_not_clear_is_reported():
    a = Cia402Axis()
    a.fault_reset()
    a.step(sw(State.FAULT))
    a.step(sw(State.FAULT))
    for _ in range(FAULT_RESET_VERIFY_CYCLES):
        assert a.step(sw(State.FAULT)) == 0x00
    assert a.fault_reset_failed and not a.resetting


def test_fault_reset_waits_for_the_fault_reaction_to_finish():
    a = Cia402Axis()
    a.fault_reset()
    for _ in range(20):
        assert a.step(sw(State.FAULT_REACTION_ACTIVE)) == 0x00
    assert a.step(sw(State.FAULT)) == 0x00
    assert a.step(sw(State.FAULT)) == 0x80
    assert a.step(sw(State.SWITCH_ON_DISABLED)) == 0x00 and a.fault_cleared
