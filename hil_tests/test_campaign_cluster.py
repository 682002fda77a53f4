"""Campaigns across processes and hosts: a worker killed mid-trial (LocalCluster), and a Dask
scheduler and workers in network namespaces of their own on this machine
(hil_tests/netns_cluster.py), the client on the host side of a veth. Same seeds, same results as
the embedded LocalCluster run and as one trial replayed alone."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from typing import Callable

import pytest
from distributed import Client, LocalCluster

from spacearm.base.paths import CONFIGS, REPO_ROOT
from spacearm.offline.campaign.replay import replay
from spacearm.offline.campaign.runner import RunSummary, run_campaign
from spacearm.offline.campaign.schema import load_campaign, trial_id
from spacearm.offline.campaign.store import ResultStore

from hil_tests.netns_cluster import NetnsCluster, NetnsUnavailable

pytestmark = pytest.mark.slow
SMOKE = CONFIGS / "campaigns" / "insertion_smoke.toml"      # 6 insertions of a few seconds each


def run_killing_mid_trial(address: str, tmp_path, kill: Callable[[Client, str], None],
                          on: str = "") -> tuple[RunSummary, list[str]]:
    """Run the smoke campaign on the scheduler at `address`; once a worker (whose address
    contains `on`) has been busy for a second, call kill(client, worker) once."""
    killed: list[str] = []

    def killer():
        with Client(address, timeout="20s") as client:
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                busy = [w for w, keys in client.processing().items() if keys and on in w]
                if busy:
                    time.sleep(1.0)                   # mid-trial (a trial takes seconds)
                    kill(client, busy[0])
                    killed.append(busy[0])
                    return
                time.sleep(0.1)

    thread = threading.Thread(target=killer)
    thread.start()
    summary = run_campaign(load_campaign(SMOKE), tmp_path / "r", scheduler=address)
    thread.join()
    assert killed, "no worker was busy to kill"
    assert (summary.ran, summary.errors) == (6, 0)
    rows = ResultStore(tmp_path / "r").rows()
    assert sorted(r["trial_id"] for r in rows) == [trial_id(i) for i in range(6)]
    return summary, killed


def test_a_killed_workers_trial_is_rerun_elsewhere(tmp_path):
    """SIGKILL the worker process that is running a trial: Dask re-runs it, nothing is lost."""
    def sigkill(client: Client, worker: str) -> None:
        pid = client.run(os.getpid, workers=[worker])[worker]
        os.kill(pid, signal.SIGKILL)       # a worker process of the cluster this test started

    with LocalCluster(n_workers=2, threads_per_worker=1, host="127.0.0.1", dashboard_address=None,
                      silence_logs=40) as cluster:
        run_killing_mid_trial(cluster.scheduler_address, tmp_path, sigkill)


def started(workers: int) -> NetnsCluster:
    cluster = NetnsCluster(workers=workers)
    try:
        return cluster.start()
    except NetnsUnavailable as exc:
        pytest.skip(f"network namespaces not available here: {exc}")


@pytest.fixture
def netns_cluster():
    cluster = started(2)
    try:
        yield cluster
    finally:
        cluster.close()


def test_campaign_on_namespace_cluster_equals_local_run_and_replay(tmp_path, netns_cluster):
    """`spacearm campaign run --scheduler tcp://10.213.N.1:8786` from the host side."""
    out = subprocess.run([sys.executable, "-m", "spacearm.console.main", "campaign", "run", str(SMOKE),
                          "--results", str(tmp_path / "netns"), "--scheduler", netns_cluster.address, "--json"],
                         capture_output=True, text=True, timeout=240, cwd=REPO_ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    remote = json.loads(out.stdout)
    assert (remote["ran"], remote["errors"], remote["workers"]) == (6, 0, 2)
    store = ResultStore(tmp_path / "netns")
    rows = store.rows()
    subnet = f"tcp://10.213.{netns_cluster.subnet}."
    assert all(r["worker"].startswith(subnet) for r in rows)       # ran inside the namespaces
    assert len({r["worker"] for r in rows}) == 2                   # on both worker hosts

    local = run_campaign(load_campaign(SMOKE), tmp_path / "local", workers=1)
    assert local.ran == 6
    assert store.outcomes() == ResultStore(tmp_path / "local").outcomes()
    assert replay(tmp_path / "netns", "t000004").matches


def test_a_worker_host_killed_mid_trial_has_its_trial_rerun_on_the_other(tmp_path, netns_cluster):
    victim = netns_cluster.worker_ip(0)
    run_killing_mid_trial(netns_cluster.address, tmp_path, lambda client, worker: netns_cluster.kill_worker_host(0),
                          on=f"//{victim}:")
    rows = ResultStore(tmp_path / "r").rows()
    assert any(r["worker"].startswith(f"tcp://{netns_cluster.worker_ip(1)}:") for r in rows)


def test_namespaces_are_gone_after_close():
    cluster = started(1)
    names = list(cluster.namespaces)
    cluster.close()
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert not any(n in listed for n in names)
    links = subprocess.run(["ip", "link"], capture_output=True, text=True).stdout
    assert f"sa23h{cluster.tag}" not in links
