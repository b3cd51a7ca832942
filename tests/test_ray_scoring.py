"""`wsp score --executor ray`: instances scored as Ray tasks (a local two-CPU Ray instance) give exactly the
local run's per-instance scores, and the report says which executor ran."""

from __future__ import annotations

import json

import pytest

from wsp_data.cli import main
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
