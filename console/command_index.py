"""Which module registers each `spacearm` word, and the word's one-line help.

`spacearm WORD ...` imports only WORD's module (console/main.py), so `oru pause` costs the
API client and typer, not the planner, the diagnosis or scipy; `spacearm --help` lists the
words from here without importing any command module. tests/console/test_import_sets.py
checks this table against the commands the modules really register and their help.
"""
from __future__ import annotations

_OPERATE = {
    "status": "Show the arm's state: mode, joints, forces, cycle statistics, stop reason.",
    "enable": "Enable all joint drives (brakes released, holding position).",
    "disable": "Hold still, then disable drives and apply brakes.",
    "reset": "Clear a protective stop (motion needs enable afterwards).",
    "stop": "Protective stop now (any console may stop the arm, control lease or not).",
    "jog": "Move one joint by DELTA (jerk-limited, within its limits).",
    "watch": "Live view of joints, forces and cycle statistics, refreshing in the terminal.",
    "move": "Point-to-point moves in joint or Cartesian space.",
    "control": "Take or release control of the arm (one console at a time).",
    "record": "Start or stop recording (MCAP + raw CAN trace).",
}

# word -> (module under spacearm.console.commands, short help as `spacearm --help` shows it)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("demo", "Main job: boot the simulated arm over CAN, run the ORU changeout, summarise."),
    "daemon": ("daemon", "Run the controller daemon until SIGINT/SIGTERM; the arm starts disabled, brakes on."),
    **{word: ("operate", text) for word, text in _OPERATE.items()},
    "oru": ("oru", "ORU changeout task flow (ORU paper Table 1)."),
    "approach": ("approach", "Closed-loop (visual servo) approach to TARGET's pre-contact pose."),
    "kin": ("kinematics", "Forward and inverse kinematics of an arm file."),
    "sim": ("sim", "Run the simulated CANopen nodes (6 joint drives, end effector, F/T sensor)."),
    "hub": ("hub", "Run the loopback CAN hub (multi-process bus on one machine, 127.0.0.1 by default)."),
    "bus": ("bus", "Look at a CAN bus: which CANopen nodes are on it."),
    "console-web": ("web", "Serve the browser console: 3-D scene with presimulation, live state, stop/reset, camera."),
    "export": ("export", "Write the recording's cycles as a wide CSV: t, q_cmd_i, q_i, dq_i, tau_i, fx..tz, ..."),
    "record-sim": ("record_sim", "Run TRAJECTORY on the simulated PLANT through the daemon over CAN (lockstep) "
                                 "and record it."),
    "diagnose": ("diagnose", "Locate, name and fit the physics the nominal simulator leaves out; show the fit improve."),
    "calibrate": ("calibrate", "Kinematic calibration: paper studies, data fits, real FR3 data."),
    "campaign": ("campaign", "Randomised trial campaigns on Dask (Monte Carlo insertions, calibration studies, "
                             "soak): resumable, one Parquet file..."),
    "config": ("config", "Validate and inspect configuration files."),
    "arm": ("arm", "Arm files: import from URDF."),
}


def module_of(word: str | None) -> str | None:
    """The module that registers `word`, or None (no word, or one this table does not know)."""
    entry = COMMANDS.get(word) if word else None
    return entry[0] if entry else None
