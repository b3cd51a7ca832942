"""`wsp score --executor ray`: instances scored as Ray tasks (a local two-CPU Ray instance) give exactly the
local run's per-instance scores, and the report says which executor ran; without an address the runner starts its
own Ray instance even where another one runs on the machine."""

from __future__ import annotations

import json

import pytest

from wsp_eval.cli import main
from wsp_eval.baselines import BASELINES
from wsp_eval.generate import per_episode, write_submission

pytest.importorskip("ray", reason="the cluster extra (ray) is not installed")


def test_ray_scores_equal_local_scores(suites_release, tmp_path):
    sub = tmp_path / "sub"
    write_submission(per_episode(BASELINES["lag"]), suites_release, sub, seeds=(0,), name="baseline:lag",
                     configs=["t2_maniskill", "t4_maniskill"], progress=False)
    reports = {}
    for executor in ("local", "ray"):
        out = tmp_path / executor
        assert main(["score", str(sub), "--release", str(suites_release), "--out", str(out), "--quiet",
                     "--workers", "2", "--executor", executor]) == 0
        reports[executor] = json.loads((out / "report.json").read_text())
    per = lambda r: {(i["config"], i["instance_id"]): i["seeds"] for i in r["instances"]}  # noqa: E731
    assert per(reports["ray"]) == per(reports["local"]) and len(per(reports["local"])) == 9
    assert reports["ray"]["timing"]["executor"] == "ray"


def test_no_address_starts_a_new_instance_beside_a_running_cluster(monkeypatch):
    """A cluster already running on the machine (named by RAY_ADDRESS, or the last `ray start`/test cluster in
    /tmp/ray) is what Ray's default `ray.init()` joins, and then refuses a CPU count: CI once failed this way while
    the multi-node build test's cluster ran beside this file. Without `--address` the runner starts its own."""
    from ray.cluster_utils import Cluster

    from wsp_eval.ray_tasks import ray_imap
    from wsp_eval.release_format import split_config

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    try:
        monkeypatch.setenv("RAY_ADDRESS", cluster.address)
        out = sorted(ray_imap(split_config, ["t1_maniskill", "t5_aloha"], workers=1, address=None))
        assert out == [("t1", "maniskill"), ("t5", "aloha")]
        import ray

        assert not ray.is_initialized()  # the runner's own instance is stopped; the other cluster is untouched
    finally:
        cluster.shutdown()
