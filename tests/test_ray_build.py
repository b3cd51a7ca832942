"""`wsp build --executor ray` on a real two-node Ray cluster on this machine: a node is lost in the middle of
the build, Ray retries its slots on the other node, and the release is byte-identical to a local build.

A build of its own (this tests building itself): the tiny T1 config of the shared `t1` release, so the
straight local build to compare against is that release.
"""

from __future__ import annotations

import subprocess
import time

import pytest

from conftest import TINY, release_files, tiny_build_command
from wsp_data.schema import STAGING_DIR

ray = pytest.importorskip("ray", reason="the cluster extra (ray) is not installed")


def test_build_loses_a_node_and_still_matches_a_local_build(tmp_path, t1_release):
    from ray.cluster_utils import Cluster

    small = 200 * 1024 * 1024  # object store per node: a tiny T1 slot is a few MB
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False,
                                                            "object_store_memory": small})
    try:
        nodes = [cluster.add_node(num_cpus=1, object_store_memory=small) for _ in range(2)]  # the head runs no slot: two worker nodes
        cluster.wait_for_nodes()
        out = tmp_path / "worldsimprobe"
        cmd = tiny_build_command(out, "--executor", "ray", "--address", cluster.address)
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        staging = out / STAGING_DIR / "t1_maniskill"
        deadline = time.time() + 900
        while not list(staging.glob("slot_*/slot.json")):  # the first slot is back: the others are in flight
            assert proc.poll() is None and time.time() < deadline, proc.communicate()
            time.sleep(0.2)
        decided = len(list(staging.glob("slot_*/slot.json")))
        cluster.remove_node(nodes[0])  # kills that node's raylet and workers, with the slot they were running
        stdout, stderr = proc.communicate(timeout=900)
        assert proc.returncode == 0, stderr[-3000:]
        assert decided < TINY["count"] and "kept 4 / 4" in stdout
        assert release_files(out) == release_files(t1_release)  # the same checksums as the straight local build
    finally:
        cluster.shutdown()
