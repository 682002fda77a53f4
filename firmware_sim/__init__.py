"""Simulated CANopen firmware of the arm's devices.

Every node serves its object dictionary from the EDS in configs/eds/ (canopen.LocalNode's
SDO server), answers NMT, produces heartbeat and EMCY, consumes the controller heartbeat
(1016h), and on each SYNC latches its RPDO commands, lets the shared ``Plant`` advance one
SYNC period (exactly once per SYNC, never on a wall-clock timer) and sends its TPDOs
(only in OPERATIONAL), sampled from the object dictionary.

    from spacearm.firmware_sim.runner import start_simulator
    sim = start_simulator("virtual:arm")                  # all nodes of configs/bus/arm.toml
    sim.node("joint_3").faults.silent = True              # fault injection (see node.Faults)
    sim.plant.joints[2].stalled = True                    # physics-level faults
    sim.stop()

As a process: ``spacearm sim --bus BUS [--plant PLANT.toml] [--bus-config BUS.toml]``.
Modules: node (generic CiA 301 slave) with its sdo_server and pdo_engine, joint_drive
(CiA 402; its power state machine in cia402_state_machine), end_effector, ft_sensor,
plant (physics + plant TOML schema), runner (Simulator), eds_builder (writes the EDS files).
"""
