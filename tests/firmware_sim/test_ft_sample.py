"""The F/T sensor's SYNC sample computes what the per-axis loop it replaced computed (issue 35):
an ideal sensor's reading is the general formula's to the bit, and the counts, the saturation,
the overload flag and its EMCYs are the loop's for any wrench, bias, scaling and limits."""
from __future__ import annotations

import math
import struct

import numpy as np
from hypothesis import given, settings, strategies as st

from spacearm.base.canopen import od
from spacearm.firmware_sim.effects import TemperatureProfile, ft_sensor_error
from spacearm.firmware_sim.plant import FtParams, Plant, PlantConfig
from spacearm.firmware_sim.runner import Simulator

_SIMS: list[Simulator] = []
_FLOATS = st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=64),
                    st.floats(-1e4, 1e4), st.sampled_from([0.0, -0.0, 0.5, -0.5, 2.5, 32767.5, -32768.5]))


def _bits(values) -> list[bytes]:
    return [struct.pack("<d", v) for v in values]


def _general_reading(plant: Plant) -> list[float]:
    """Plant.ft_reading's general path (as it was for every sensor before)."""
    ft = plant.config.ft
    reading = ft_sensor_error(plant.wrench, plant.time, plant.config.temperature.delta(plant.time), ft.bias,
                              ft.drift, ft.scale_error, ft.temp_coefficient)
    return [w + 0.0 for w in reading]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(_FLOATS, st.just(math.inf), st.just(-math.inf)), min_size=6, max_size=6),
       st.floats(0.0, 1e6), st.sampled_from([0.0, -0.0]), st.booleans(), st.booleans())
def test_an_ideal_sensor_reads_the_general_formula_to_the_bit(wrench, t, zero, numpy_wrench, warming):
    """Bits and types (a contact world's wrench holds numpy scalars), with the temperature
    constant or changing over the run."""
    temperature = TemperatureProfile(points=((0.0, 20.0), (600.0, 35.0))) if warming else TemperatureProfile()
    plant = Plant.create(6, PlantConfig(ft=FtParams(bias=(zero,) * 6, drift=(zero,) * 6), temperature=temperature))
    plant.wrench, plant.time = [np.float64(w) for w in wrench] if numpy_wrench else list(wrench), t
    reading, general = plant.ft_reading(), _general_reading(plant)
    assert _bits(reading) == _bits(general)
    assert [type(w) for w in reading] == [type(w) for w in general]


def _loop_sample(raw, bias, kf, kt, flim, tlim) -> tuple[list[int], bool]:
    """The per-axis loop _sample ran before."""
    overload = False
    values = []
    for i, value in enumerate(raw):
        value -= bias[i]
        scale, limit = (kf, flim) if i < 3 else (kt, tlim)
        counts = round(value * scale)
        if abs(value) > limit or not -32768 <= counts <= 32767:
            overload = True
        values.append(max(-32768, min(32767, counts)))
    return values, overload


def _sensor():
    """The default bus config's F/T sensor, powered on, not on a bus (built once: the EDS files
    are slow to load)."""
    if not _SIMS:
        sim = Simulator("virtual:ft-sample-test")
        sim.bus = object()        # not None: what the node sends goes nowhere
        sim._send_frame = sim._send_frames = lambda *frames: None
        next(n for n in sim.nodes.values() if n.device_type == "ft_sensor").power_on()
        _SIMS.append(sim)
    sim = _SIMS[0]
    node = next(n for n in sim.nodes.values() if n.device_type == "ft_sensor")
    node.emcys = []
    node.emcy = lambda *args: node.emcys.append(args)
    return sim, node


@settings(max_examples=300, deadline=None)
@given(st.lists(st.lists(_FLOATS, min_size=6, max_size=6), min_size=1, max_size=4),
       st.lists(_FLOATS, min_size=6, max_size=6),
       st.integers(1, 2000), st.integers(1, 20000), st.integers(0, 65535), st.integers(0, 65535))
def test_the_sample_counts_saturates_and_flags_overload_as_the_loop(wrenches, bias, kf, kt, flim, tlim):
    sim, node = _sensor()
    for index, sub, value in ((od.FT_FORCE_COUNTS_PER_N, 0, kf), (od.FT_TORQUE_COUNTS_PER_NM, 0, kt),
                              (od.FT_OVERLOAD_LIMIT, 1, flim), (od.FT_OVERLOAD_LIMIT, 2, tlim)):
        node.put(index, sub, value)      # a write drops the cached scaling: read again
    node.bias, node.overload = list(bias), False
    expected_overload = False
    for wrench in wrenches:
        sim.plant.wrench = list(wrench)
        raw = sim.plant.ft_reading()
        try:
            expected, overload = _loop_sample(raw, bias, kf, kt, flim, tlim)
        except (OverflowError, ValueError) as exc:      # the loop raised: so does the sample
            try:
                node._sample()
            except type(exc):
                return
            raise AssertionError("the sample did not raise") from exc
        emcys = len(node.emcys)
        node._sample()
        assert [node.get(od.FT_VALUES, i) for i in range(1, 7)] == expected
        assert node.overload is overload
        assert node.get(od.FT_STATUS) & od.FT_STATUS_OVERLOAD == (od.FT_STATUS_OVERLOAD if overload else 0)
        assert len(node.emcys) - emcys == (overload != expected_overload)
        expected_overload = overload


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.lists(_FLOATS, min_size=6, max_size=6), st.integers(1, 3), st.booleans(),
                          st.sampled_from([None, 1, 2]), st.booleans(), st.booleans()), min_size=1, max_size=5),
       st.lists(_FLOATS, min_size=6, max_size=6), st.integers(1, 2000), st.integers(0, 65535))
def test_a_repeated_reading_samples_as_a_fresh_one(steps, bias, kf, flim):
    """A reading equal to the last (the sensor at rest) reuses the last counts: the stored
    values, status, overload flag and EMCYs are those of a sample worked out afresh, whatever
    happens between (a tare, the bias changed in place, numpy scalars, the overload flag or the
    scaling changed from outside)."""
    sim, node = _sensor()
    traces = []
    for fresh in (False, True):
        node.put(od.FT_FORCE_COUNTS_PER_N, 0, kf)
        node.put(od.FT_OVERLOAD_LIMIT, 1, flim)
        node.bias, node.overload, node.tared, node.pending_tare = list(bias), False, False, None
        node._last_sample = (None,) * 7
        node.emcys = []
        trace = []
        for wrench, repeats, numpy_wrench, tare, poke_bias, flip in steps:
            for _ in range(repeats):
                if fresh:
                    node._last_sample = (None,) * 7
                sim.plant.wrench = [np.float64(w) for w in wrench] if numpy_wrench else list(wrench)
                try:
                    with np.errstate(over="ignore"):      # a numpy reading times its scale may overflow
                        node._sample()
                except (OverflowError, ValueError) as exc:
                    trace.append(type(exc).__name__)
                    continue
                trace.append(([node.get(od.FT_VALUES, i) for i in range(1, 7)], node.get(od.FT_STATUS),
                              node.overload, list(node.emcys)))
            node.pending_tare = tare
            if poke_bias:
                node.bias[0] = node.bias[0] + 1.0
            if flip:
                node.overload = not node.overload
        traces.append(repr(trace))
    assert traces[0] == traces[1]
