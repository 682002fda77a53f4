"""Plugs the impedance mode and the ORU task runner into a daemon: mode factories and the
`oru.*` commands of the command API (validated here, applied inside the cycle)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from pydantic import Field

from spacearm.base.config.scene import DEFAULT_SCENE, load_scene
from spacearm.controller.daemon.api_handlers import Args, NoArgs
from spacearm.controller.daemon.api_errors import ErrorCode
from spacearm.controller.daemon.command_api import ApiError
from spacearm.controller.daemon.core import CommandRefused
from spacearm.controller.impedance.config import DEFAULT_IMPEDANCE, load_impedance
from spacearm.controller.impedance.mode import ContactTask, ImpedanceMode
from spacearm.controller.oru.config import DEFAULT_CHANGEOUT, load_changeout
from spacearm.controller.oru.flow import FlowContext
from spacearm.controller.oru.runner import OruTaskRunner


class OruRunArgs(Args):
    stages: list[int] | None = Field(default=None, min_length=1, max_length=8,
                                     description="1-based stage numbers to run, in order (default: all)")


class OruSetup:
    """Configuration the runner needs, loaded (and checked) once when the daemon starts."""

    def __init__(self, daemon, scene: Path = DEFAULT_SCENE, impedance: Path = DEFAULT_IMPEDANCE,
                 changeout: Path = DEFAULT_CHANGEOUT):
        self.daemon = daemon
        self.scene = load_scene(scene)
        self.impedance = load_impedance(impedance)
        self.changeout = load_changeout(changeout)
        self.last: OruTaskRunner | None = None      # the latest run, for status after it ended
        for stage in self.changeout.stages:
            self.scene.store(stage.store)      # unknown store names fail at start-up
        # Other cycle periods (the 4 ms daemon benchmark) still start; only the ORU flow is refused.
        self.problem: str | None = None
        if abs(self.impedance.period - daemon.options.period) > 1e-12:
            self.problem = (f"{impedance}: impedance period {self.impedance.period} s differs from the "
                            f"daemon's {daemon.options.period} s cycle")

    def runner(self, q_start: np.ndarray, stages: list[int] | None = None) -> OruTaskRunner:
        d = self.daemon
        ctx = FlowContext(d.model, d.planner, self.scene, self.changeout, self.impedance,
                          d.mode_factories, np.asarray(q_start, float).copy())
        return OruTaskRunner(ctx, stages)

    def impedance_mode(self, q_start: np.ndarray, task: ContactTask) -> ImpedanceMode:
        return ImpedanceMode(self.daemon.model, self.impedance, task, q_start)


def install_oru(daemon) -> OruSetup:
    setup = OruSetup(daemon)
    daemon.mode_factories["oru"] = setup.runner
    daemon.mode_factories["impedance"] = setup.impedance_mode
    core, handlers = daemon.core, daemon.handlers

    def runner_now() -> OruTaskRunner:
        mode = core.mode
        if not isinstance(mode, OruTaskRunner):
            raise CommandRefused("no ORU changeout is running", ErrorCode.NOT_RUNNING)
        return mode

    def run(a: OruRunArgs) -> Any:
        if setup.problem is not None:
            raise ApiError(f"ORU changeout unavailable: {setup.problem}", ErrorCode.UNAVAILABLE)
        stages = None
        if a.stages is not None:
            n = len(setup.changeout.stages)
            if any(not 1 <= s <= n for s in a.stages):
                raise ApiError(f"stages: each must be 1..{n}, got {a.stages}", ErrorCode.BAD_ARGUMENT)
            stages = [s - 1 for s in a.stages]

        def start(t: float, m) -> Any:
            runner = setup.runner(core.motion_start(t, m), stages)
            answer = core.start_planned(t, m, runner, None)
            setup.last = runner
            return answer
        return handlers._in_cycle(start)

    def _logged(t: float, what: str, action) -> str:
        """Pause/resume as events (status, recording): what was asked and the runner's answer."""
        state = action()
        core._event(t, "oru", f"{what}: ORU changeout {state}")
        return state

    def status(t: float, m) -> dict:
        runner = setup.last
        if runner is None:
            return {"state": "idle"}
        out = runner.status()
        if core.mode is not runner and out["state"] in ("running", "paused", "pausing", "resuming"):
            # The core stopped it (supervision finding, operator stop, disable).
            out["state"] = "interrupted"
            out["failure"] = core.stop_reason.message if core.stop_reason else f"arm {core.state}"
        return out

    handlers.table.update({
        "oru.run": (OruRunArgs, True, run),
        "oru.pause": (NoArgs, True, lambda a: handlers._in_cycle(lambda t, m: _logged(t, "pause", runner_now().pause))),
        "oru.resume": (NoArgs, True, lambda a: handlers._in_cycle(lambda t, m: _logged(t, "resume", runner_now().resume))),
        "oru.abort": (NoArgs, False, lambda a: handlers._in_cycle(lambda t, m: runner_now().abort())),
        "oru.status": (NoArgs, False, lambda a: handlers._in_cycle(status)),
    })
    return setup
