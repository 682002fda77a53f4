"""A campaign across hosts: Dask scheduler and workers in their own network namespaces on this
machine (hil_tests/netns_cluster.py), the client on the host side of a veth. Same seeds, same
results as the embedded LocalCluster run and as one trial replayed alone."""
from __future__ import annotations

import pytest

from spacearm.base.paths import CONFIGS
from spacearm.offline.campaign.replay import replay
from spacearm.offline.campaign.runner import run_campaign
from spacearm.offline.campaign.schema import load_campaign
from spacearm.offline.campaign.store import ResultStore

from hil_tests.netns_cluster import NetnsCluster, NetnsUnavailable

pytestmark = pytest.mark.slow


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
    campaign = load_campaign(CONFIGS / "campaigns" / "insertion_smoke.toml")
    remote = run_campaign(campaign, tmp_path / "netns", scheduler=netns_cluster.address)
    assert (remote.ran, remote.errors, remote.workers) == (6, 0, 2)
    store = ResultStore(tmp_path / "netns")
    rows = store.rows()
    subnet = f"tcp://10.213.{netns_cluster.subnet}."
    assert all(r["worker"].startswith(subnet) for r in rows)       # ran inside the namespaces
    assert len({r["worker"] for r in rows}) == 2                   # on both worker hosts

    local = run_campaign(campaign, tmp_path / "local", workers=1)
    assert local.ran == 6
    assert store.outcomes() == ResultStore(tmp_path / "local").outcomes()
    assert replay(tmp_path / "netns", "t000004").matches


def test_a_worker_host_killed_mid_trial_has_its_trial_rerun_on_the_other(tmp_path, netns_cluster):
    import threading
    import time

    from distributed import Client

    campaign = load_campaign(CONFIGS / "campaigns" / "insertion_smoke.toml")
    victim = netns_cluster.worker_ip(0)
    killed: list[str] = []

    def kill_when_busy():
        with Client(netns_cluster.address, timeout="20s") as client:
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline:
                busy = [w for w, keys in client.processing().items() if keys and f"//{victim}:" in w]
                if busy:
                    time.sleep(1.0)                   # mid-trial
                    netns_cluster.kill_worker_host(0)
                    killed.extend(busy)
                    return
                time.sleep(0.1)

    killer = threading.Thread(target=kill_when_busy)
    killer.start()
    summary = run_campaign(campaign, tmp_path / "r", scheduler=netns_cluster.address)
    killer.join()
    assert killed, "worker host 0 never ran a trial"
    assert (summary.ran, summary.errors) == (6, 0)
    rows = ResultStore(tmp_path / "r").rows()
    assert len({r["trial_id"] for r in rows}) == 6
    assert any(r["worker"].startswith(f"tcp://{netns_cluster.worker_ip(1)}:") for r in rows)


def test_namespaces_are_gone_after_close():
    import subprocess
    cluster = started(1)
    names = list(cluster.namespaces)
    cluster.close()
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert not any(n in listed for n in names)
    links = subprocess.run(["ip", "link"], capture_output=True, text=True).stdout
    assert f"sa23h{cluster.tag}" not in links
