"""A daemon's recording as other tools see it: opened with the `mcap` library's own reader,
every channel has a JSON schema every message validates against, log times are UTC wall-clock
dates (Foxglove shows the day of the run, not 1970), our reader still gives controller time,
and the raw CAN trace rotates at its size limit keeping only the configured number of files."""
from __future__ import annotations

import json
import threading
import time
import uuid

import jsonschema
import pytest
from mcap.reader import make_reader

from spacearm.controller.recording.can_trace import TraceLimit
from spacearm.controller.recording.channels import CHANNELS
from spacearm.controller.recording.mcap_reader import read_recording

TRACE_LIMIT = TraceLimit(max_bytes=20_000, keep=2)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    from spacearm.firmware_sim.runner import start_simulator
    runs = tmp_path_factory.mktemp("runs")
    bus = f"virtual:rec-{uuid.uuid4().hex[:8]}"
    sim = start_simulator(bus, plant="configs/plant/oru_testbed_nominal.toml", time_base="sync")
    daemon = Daemon(DaemonOptions(bus=bus, clock="lockstep", api=None, record_dir=runs,
                                  can_trace_limit=TRACE_LIMIT))
    started_ns = time.time_ns()
    try:
        daemon.start()
        runner = threading.Thread(target=daemon.run, args=(600,), daemon=True)
        runner.start()
        key = daemon.lease.take("test")
        daemon.handlers.handle(None, "enable", {"lease": key})      # events on /events
        runner.join(120)
    finally:
        daemon.request_stop()
        daemon.shutdown()
        sim.stop()
    [path] = runs.glob("*.mcap")
    return path, started_ns, time.time_ns()


def test_every_message_validates_against_its_channel_schema(recorded):
    path, _, _ = recorded
    counts: dict[str, int] = {}
    with open(path, "rb") as handle:
        reader = make_reader(handle)
        for schema, channel, message in reader.iter_messages():
            assert schema is not None and schema.encoding == "jsonschema" and channel.message_encoding == "json"
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        declared = {c.topic for c in reader.get_summary().channels.values()}
    assert declared == set(CHANNELS)
    assert counts.get("/cycle", 0) >= 500 and counts.get("/events", 0) >= 1 and counts.get("/stats", 0) >= 1


def test_log_times_are_utc_wall_clock_and_our_reader_gives_controller_time(recorded):
    path, started_ns, ended_ns = recorded
    with open(path, "rb") as handle:
        times = [m.log_time for _, _, m in make_reader(handle).iter_messages(topics=["/cycle"])]
    assert started_ns - 5e9 <= times[0] <= ended_ns           # the run's real date, not 1970
    assert times == sorted(times)
    first = next(m for m in read_recording(path).messages if m.topic == "/cycle")
    assert first.time == pytest.approx(first.data["t"], abs=1e-6)


def test_the_raw_can_trace_rotates_and_keeps_the_configured_files(recorded):
    path, _, _ = recorded
    log = path.with_suffix(".can.log")
    rotated = sorted(log.parent.glob(log.name + ".*"))
    assert [p.name for p in rotated] == [f"{log.name}.{i}" for i in range(1, TRACE_LIMIT.keep + 1)]
    for file in [log, *rotated]:
        assert file.stat().st_size <= TRACE_LIMIT.max_bytes + 256 * 64   # checked every 256 frames
    assert rotated[0].read_text().splitlines()[0].startswith("(")       # candump format, complete lines
