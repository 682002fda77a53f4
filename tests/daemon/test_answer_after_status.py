"""A console that reads `status` right after a command's "ok" sees that command (CI, stop 37:
`move_joints` was answered while its cycle still published the status of the cycle before it,
a console saw mode "hold", took the arm for at rest at ready, and its next command was refused
with "move_joints still in progress"). The cycle is held between taking the command and
publishing its status until the console has had its answer, or for 0.5 s: answered before the
status, the console reads the old mode; answered after, the new one."""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

from tests.daemon.lockstep_script import scripted_daemon

PLANT = "configs/plant/oru_testbed_nominal.toml"


def test_status_read_right_after_the_answer_shows_the_command():
    with scripted_daemon(PLANT) as script:
        daemon = script.daemon
        script.run(5)
        assert daemon.status()["mode"] in (None, "hold")
        answered = threading.Event()
        write = daemon.hardware.write

        def held_write(*args, **kwargs):
            if daemon.core.mode is not None and daemon.core.mode.name == "move_joints":
                answered.wait(0.5)            # the console's answer, if it comes before the status
            return write(*args, **kwargs)
        daemon.hardware.write = held_write

        def console():
            result = daemon.handlers.handle(None, "move_joints", {"lease": script.lease,
                                                                  "q": [0.3, -0.2, 1.2, -1.3, 0.4, -1.2]})
            answered.set()
            return result, daemon.status()

        with ThreadPoolExecutor(1) as api:
            reply = api.submit(console)
            while not reply.done():          # move_joints takes two cycles: its start, then the motion
                if daemon.core.requests_waiting:
                    daemon.cycle_once()
            result, status = reply.result()
        daemon.hardware.write = write
        assert result["mode"] == "move_joints"
        assert status["mode"] == "move_joints", f"status after the answer still showed mode {status['mode']!r}"
        assert status["motions_finished"] < result["motion"]
