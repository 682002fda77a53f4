"""Bring-up of the network (the CiA 302 boot process): reset communication; each node, once its
boot-up is in, configured (drivers/bringup.py, nodes in parallel) and started on its own; verify
all are OPERATIONAL; and the boot-slave process again for a node that reboots during operation.

``BootMaster`` is a part of ``ArmNetwork`` (drivers/network.py).
"""
from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor

from spacearm.base.canopen import od
from spacearm.drivers.bringup import NodeBringup
from spacearm.drivers.devices import DeviceDriver, JointDriver
from spacearm.drivers.errors import BootError, DriverError

logger = logging.getLogger(__name__)

# Nodes configured at once at boot: each waits on its own SDO answers, so they overlap
MAX_PARALLEL_CONFIG = 16


class _NoBootup(Exception):
    """A node's boot-up did not come before the boot deadline (collected into one BootError)."""


class BootMaster:
    # ------------------------------------------------------------------ bring-up
    def boot(self, timeout: float | None = None) -> None:
        """Reset communication of all nodes; then for each node, as soon as its boot-up is in
        (nodes side by side): configure it by SDO (heartbeat, SYNC, scaling, limits, PDO
        mapping) and start it, as CiA 302's boot-slave process starts each slave on its own; a
        node's wait for OPERATIONAL thus overlaps the others' configuration. Verify every node
        reports OPERATIONAL. Raises BootError naming the node(s) at fault; then no node is
        left started (NMT pre-operational to all)."""
        self.connect()
        timeout = self.config.bus.boot_timeout if timeout is None else timeout
        self._monitoring = False
        with self._cv:
            self._booted.clear()
            for h in self.health.values():
                h.alive, h.nmt_state, h.last_heartbeat = False, None, None
        self._nmt(od.NMT_RESET_COMMUNICATION)
        deadline = time.monotonic() + timeout
        try:
            missing = self._configure_all(list(self.drivers.values()), deadline)
            if missing:
                raise BootError(f"boot failed: no boot-up message within {timeout:.1f} s from "
                                + ", ".join(d.label for d in missing))
            self._monitoring = True
            # three heartbeat periods on time, else what is left of the boot's time: a starved
            # process's heartbeats come late, and a node late within boot_timeout is no fault
            wait = max(3.0 * max(n.heartbeat_period for n in self.config.nodes) + 0.2,
                       deadline - time.monotonic())
            with self._cv:
                self._cv.wait_for(lambda: all(h.nmt_state == od.NMT_STATE_OPERATIONAL
                                              for h in self.health.values()), timeout=wait)
                not_op = [self.drivers[n] for n, h in self.health.items()
                          if h.nmt_state != od.NMT_STATE_OPERATIONAL]
            if not_op:
                raise BootError("boot failed: not OPERATIONAL after NMT start: " + ", ".join(
                    f"{d.label} reports {self.health[d.name].nmt_state_name}" for d in not_op))
        except Exception:
            self._monitoring = False
            self._nmt(od.NMT_PRE_OPERATIONAL)
            raise

    def _configure_all(self, drivers: list[DeviceDriver], deadline: float) -> list[DeviceDriver]:
        """The boot-slave process of every node side by side; the first failure (in bus-file
        order) is raised; the nodes whose boot-up never came are returned."""
        with ThreadPoolExecutor(max_workers=max(1, min(MAX_PARALLEL_CONFIG, len(drivers))),
                                thread_name_prefix="boot-slave") as pool:
            futures = [pool.submit(self._boot_slave, d, deadline) for d in drivers]
            results = [(f.exception(), d) for f, d in zip(futures, drivers)]
        for error, _ in results:
            if error is not None and not isinstance(error, _NoBootup):
                raise error
        return [d for error, d in results if isinstance(error, _NoBootup)]

    def _boot_slave(self, driver: DeviceDriver, deadline: float) -> None:
        with self._cv:
            if not self._cv.wait_for(lambda: driver.node_id in self._booted,
                                     timeout=max(0.0, deadline - time.monotonic())):
                raise _NoBootup(driver.label)
        self._configure(driver)
        self._start(driver)

    def _start(self, driver: DeviceDriver) -> None:
        with self._cv:
            h = self.health[driver.name]
            h.last_heartbeat, h.alive = time.monotonic(), True
        self._nmt(od.NMT_START, driver.node_id)

    def recover(self, node: str | int, timeout: float = 1.0) -> None:
        """The boot-slave process for one node (after a reboot): configure it by SDO again and
        start it. Its CiA 402 axis restarts from SWITCH ON DISABLED and stays there until
        enabled again (its goal was dropped when it rebooted)."""
        driver = self._driver(node)
        with self._slave_lock(driver):
            self._configure(driver)
            self._start(driver)
            with self._cv:
                ok = self._cv.wait_for(lambda: self.health[driver.name].nmt_state == od.NMT_STATE_OPERATIONAL,
                                       timeout=timeout)
        if not ok:
            raise BootError(f"{driver.label} not OPERATIONAL after recovery "
                            f"(reports {self.health[driver.name].nmt_state_name})")

    def _slave_lock(self, driver: DeviceDriver) -> threading.Lock:
        with self._cv:
            return self._slave_locks.setdefault(driver.name, threading.Lock())

    def _configure(self, driver: DeviceDriver) -> None:
        """Configure one node from its EDS and configuration (drivers/bringup.py)."""
        previous = self.bringup.get(driver.name)
        report = NodeBringup(self, driver, self.config.bus).run()
        if previous is not None:
            report.reboots, report.reboot = previous.reboots, previous.reboot
        self.bringup[driver.name] = report
        if report.node_guarding:       # polled by the monitor thread; answers arrive as heartbeats
            self._guarded[driver.node_id] = 0.0

    # ------------------------------------------------------------------ reboot during operation
    def _on_reboot(self, driver: DeviceDriver) -> None:
        """A boot-up message from a node in operation (called by the heartbeat consumer with the
        network's lock held): its drive lost its state and its configuration. The event
        (``bootup``) lets the daemon stop the arm; the drive's goal is dropped so it never
        re-enables by itself; the boot-slave process runs again in its own thread (SDO must not
        wait in the receive thread) and ends in a ``reconfigured`` or ``reconfigure_failed`` event."""
        report = self.bringup.get(driver.name)
        if report is not None:
            report.reboots += 1
            report.reboot = f"rebooted during operation ({time.strftime('%H:%M:%S')} UTC); reconfiguring"
        if isinstance(driver, JointDriver):
            driver.axis.disable()
        self._event("bootup", driver, f"{driver.label} rebooted (boot-up message): reconfiguring it")
        if not self._stop.is_set():
            threading.Thread(target=self._reconfigure, args=(driver,), name=f"boot-slave-{driver.node_id}",
                             daemon=True).start()

    def _reconfigure(self, driver: DeviceDriver) -> None:
        try:
            self.recover(driver.name, timeout=3.0 * driver.cfg.heartbeat_period + 0.5)
        except DriverError as exc:
            outcome, kind = f"reconfiguration FAILED: {exc}", "reconfigure_failed"
        except Exception as exc:     # the network closed under it
            if self._stop.is_set():
                return
            logger.exception("reconfiguring %s", driver.label)
            outcome, kind = f"reconfiguration FAILED: {type(exc).__name__}: {exc}", "reconfigure_failed"
        else:
            writes = self.bringup[driver.name].sdo_writes
            outcome, kind = f"reconfigured and OPERATIONAL again ({writes} SDO writes)", "reconfigured"
        report = self.bringup.get(driver.name)
        if report is not None:
            report.reboot = report.reboot.replace("reconfiguring", outcome)
        self._event(kind, driver, f"{driver.label}: {outcome}")
