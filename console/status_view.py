"""Render the daemon's status for people: degrees, millimetres and milliseconds."""
from __future__ import annotations

import math

TYPE_CHECKING = False   # typing itself is ~10 ms of the console's start-up: annotations only
if TYPE_CHECKING:
    from typing import Any

# cycles before the statistics' level means anything: the first cycles include the start-up
# (the cycle run before the API opens waits for the whole boot), and one slow sample is the p99
STATS_SETTLED = 50


def _deg(value: float | None) -> str:
    return "-" if value is None else f"{math.degrees(value):9.3f}"


def status_lines(status: dict[str, Any]) -> list[str]:
    stats = status.get("stats") or {}
    control = status.get("control") or {}
    lines = [
        f"state {status['state']}   mode {status.get('mode') or '-'}   "
        f"t {status.get('time', 0.0):.2f} s   sync {status.get('sync_counter', '-')}",
    ]
    if status.get("stop_reason"):
        lines.append(f"protective stop: {status['stop_reason']}")
        late = [name for name, p in ((status.get("nodes") or {}).get("peers") or {}).items() if p["level"] != "ok"]
        if late and (status.get("stop") or {}).get("code") in ("pdo_missing", "heartbeat_lost"):
            lines.append(f"  likely cause: the {' and the '.join(late)} reported itself late (below); "
                         "the nodes it hosts or carries are not at fault")
    if tool_text(status):
        lines.append(tool_text(status))
    lines.append(f"control: {control.get('holder') or 'free'}   "
                 f"recording: {(status.get('recording') or {}).get('path') or 'off'}")
    if stats:
        lines.append(
            f"cycle: period error median {1e3 * stats['period_error_median']:.3f} ms, "
            f"p99 {1e3 * stats['period_error_p99']:.3f} ms, max {1e3 * stats['period_error_max']:.3f} ms; "
            f"execution p99 {1e3 * stats['execution_p99']:.3f} ms "
            f"(compute {1e3 * stats.get('compute_p99', float('nan')):.3f} ms); overruns {stats['overruns']}"
            f"{overrun_causes_text(stats)} "
            f"[{stats['level'] if stats.get('cycles', STATS_SETTLED) >= STATS_SETTLED else 'starting'}]"
            + (f"; scheduling {status['scheduling']}" if status.get("scheduling") else ""))
    nodes = status.get("nodes") or {}
    if nodes.get("level") not in (None, "ok"):
        lines.append(f"WARNING {nodes['message']} (answer p99 {1e3 * nodes['io_wait_p99']:.1f} ms of "
                     f"{1e3 * nodes['budget']:.1f} ms)")
    elif nodes.get("host_stalled_cycles"):
        lines.append(f"note: {nodes['message']}")
    peers = nodes.get("peers") or {}
    if peers:       # the simulator's and the hub's own view of their timing, beside the daemon's
        lines.append("their own timing: " + "; ".join(p["message"] for p in peers.values()))
    wrench = status.get("wrench")
    if wrench:
        lines.append("wrench: F " + " ".join(f"{v:7.2f}" for v in wrench[:3]) + " N   T "
                     + " ".join(f"{v:6.3f}" for v in wrench[3:]) + " N m")
    if status.get("end_effector"):
        lines.append(f"end effector: {status['end_effector']}")
    return lines + bringup_lines(status.get("bringup") or {})


def bringup_lines(bringup: dict[str, dict[str, Any]]) -> list[str]:
    """What bring-up could not do as the bus file asked, per node, and the node reboots since."""
    lines = []
    skipped = {node: [s.split()[0] for s in r.get("skipped", [])] for node, r in bringup.items()}
    if any(skipped.values()):
        lines.append("absent optional objects (skipped at bring-up): "
                     + "; ".join(f"{node} {' '.join(objs)}" for node, objs in skipped.items() if objs))
    for node, report in bringup.items():
        lines += [f"{node}: {text}" for text in report.get("refused", [])]     # each with its fallback
        if report.get("read_only"):
            lines.append(f"{node}: read-only, the device's value used: {' '.join(report['read_only'])}")
        if report.get("reboot"):
            lines.append(f"{node}: {report['reboot']} ({report.get('reboots', 1)} reboot(s) so far)")
    return lines


def tool_text(status: dict[str, Any]) -> str | None:
    """The measured tool pose as people read it: mm and degrees (the daemon sends m and rad)."""
    tool = status.get("tool")
    if not tool:
        return None
    x, y, z = (1e3 * v for v in tool["xyz"])
    r, p, w = (math.degrees(v) for v in tool["rpy"])
    return (f"tool (base frame): x {x:.1f} mm  y {y:.1f} mm  z {z:.1f} mm  "
            f"roll {r:.2f} deg  pitch {p:.2f} deg  yaw {w:.2f} deg")


def limit_margin(joint: dict[str, Any]) -> tuple[float, str] | None:
    """(distance to the nearer joint limit, which one: 'min'/'max'), in the joint's units."""
    if joint.get("q_min") is None or joint.get("q_max") is None:
        return None
    below, above = joint["q"] - joint["q_min"], joint["q_max"] - joint["q"]
    return (below, "min") if below <= above else (above, "max")


def _margin_text(joint: dict[str, Any]) -> str:
    margin = limit_margin(joint)
    return "-" if margin is None else f"{math.degrees(margin[0]):8.2f} {margin[1]}"


EVENTS_SHOWN = 5


def event_lines(status: dict[str, Any], count: int = EVENTS_SHOWN) -> list[str]:
    """The last events, newest last, each with its code: `t s [code] kind: message`."""
    lines = []
    for event in (status.get("events") or [])[-count:]:
        code = event.get("code") or event.get("kind")
        where = " ".join(f"{k} {event[k]}" for k in ("node", "joint") if event.get(k) is not None)
        lines.append(f"  {event.get('t', 0.0):9.2f} s [{code}] {event.get('message', '')}"
                     + (f" ({where})" if where else ""))
    return lines


def render_status(status: dict[str, Any]) -> str:
    lines = status_lines(status)
    lines.append(f"{'joint':<16}{'q deg':>10}{'target deg':>12}{'dq deg/s':>10}{'tau N m':>9}  enabled"
                 f"{'to limit deg':>16}")
    for joint in status.get("joints", []):
        lines.append(f"{joint['name']:<16}{_deg(joint['q']):>10}{_deg(joint.get('q_cmd')):>12}"
                     f"{_deg(joint['dq']):>10}{joint['tau']:9.2f}  {'yes' if joint['enabled'] else 'no ':<7}"
                     f"{_margin_text(joint):>16}")
    events = event_lines(status)
    if events:
        lines.append(f"last events ({len(events)} of {len(status.get('events') or [])}):")
        lines += events
    return "\n".join(lines)


def status_table(status: dict[str, Any]):
    """The live view for `watch` (rich imported here: `status` and `stop` stay light)."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text
    table = Table(title=None, expand=False)
    for column in ("joint", "q deg", "target deg", "dq deg/s", "tau N m", "enabled", "to limit deg"):
        table.add_column(column, justify="left" if column == "joint" else "right")
    for joint in status.get("joints", []):
        table.add_row(joint["name"], _deg(joint["q"]), _deg(joint.get("q_cmd")), _deg(joint["dq"]),
                      f"{joint['tau']:.2f}", "yes" if joint["enabled"] else "no", _margin_text(joint))
    header = Text("\n".join(status_lines(status) + event_lines(status, 3)),
                  style="bold red" if status["state"] == "stopped" else "")
    return Group(header, table)


def overrun_causes_text(stats: dict) -> str:
    """"; by cause: host 1, gil 1" for the cycle statistics' judged overruns, "" for none."""
    causes = stats.get("overrun_causes") or {}
    return "; by cause: " + ", ".join(f"{cause} {n}" for cause, n in causes.items()) if causes else ""
