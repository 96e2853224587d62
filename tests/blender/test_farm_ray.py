"""The Ray backend on a real local Ray cluster started here (a head and a second node, both on
127.0.0.1): a worker killed mid-shard is retried, the dataset validates with every frame
exactly once, and it is the same, bit for bit, as the local backend's render of the plan."""

from __future__ import annotations

import os
import signal

import pytest
from tests.support.farm_helpers import SMALL, compare, frame_keys, leave_nothing_running, lease_holder, staged, start_synth, synth, \
    wait_for

pytest.importorskip("bpy")
ray = pytest.importorskip("ray")

pytestmark = [pytest.mark.blender, pytest.mark.slow]


#: Ray resolves "127.0.0.1" to the machine's outward address unless told that this is a
#: one-machine cluster; the test stays on the loopback interface.
LOOPBACK = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_USAGE_STATS_ENABLED": "0"}


@pytest.fixture(scope="module")
def cluster():
    from ray.cluster_utils import Cluster

    saved = {k: os.environ.get(k) for k in LOOPBACK}
    os.environ.update(LOOPBACK)  # for the nodes' processes, started from this one
    c = Cluster(initialize_head=True, connect=False,
                head_node_args={"num_cpus": 1, "node_ip_address": "127.0.0.1", "include_dashboard": False})
    try:
        c.add_node(num_cpus=1, node_ip_address="127.0.0.1")
        c.wait_for_nodes()
        yield c
    finally:
        c.shutdown()  # stops every process of both nodes
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def test_ray_render_with_a_killed_worker_is_retried_and_equals_local(cluster, farm_reference, tmp_path):
    out = tmp_path / "ds"
    ctl = start_synth("render", *SMALL, "--out", out, "--backend", "ray", "--ray-address", cluster.address,
                      "--shards-per-worker", "1", "--retries", "2", "--progress-every", "5", extra_env=LOOPBACK)
    killed = None
    try:
        def a_worker_mid_shard():
            for p in staged(out):
                h = lease_holder(out, p.parent.name)
                if h is not None:
                    return h["pid"]
            return None

        killed = wait_for(a_worker_mid_shard, "a worker with a staged frame", 300)
        os.kill(killed, signal.SIGKILL)
        stdout, err = ctl.communicate(timeout=900)
    finally:
        leave_nothing_running(ctl, out)
    assert ctl.returncode == 0, stdout + err
    assert "6/6 frames in 3/3 shards committed" in stdout
    assert len(list(out.glob("logs/ray-*/batch_*.1.log"))) == 1, "exactly one task ran a second attempt"
    synth("validate", out)
    assert frame_keys(out) == frame_keys(farm_reference)  # every frame exactly once
    rc, text = compare(farm_reference, out)
    assert rc == 0, text
