"""A real tiny T3 release (one group of eight PickCube sources sharing a scene seed, rendered, LeRobot-written):
both loaders, all eight source groups with honest provenance, every stored stream replays to its stored states
in the simulator, and the oracle scores 100 per source group."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import instance_rows, open_lerobot

from wsp_data.builders.t3 import OPERATOR_GROUPS, POLICY_GROUPS, SOURCE_GROUPS
from wsp_data.schema import MAX_OBJECTS, OBJECT_POSES_KEY

CONFIG = "t3_maniskill"


@pytest.fixture(scope="module")
def rows(suites_release):
    return instance_rows(suites_release, CONFIG)


@pytest.fixture(scope="module")
def ds(suites_release):
    return open_lerobot(suites_release, CONFIG)


def test_source_groups_match_the_sources():
    from wsp_data.platforms.maniskill.t3 import OPERATORS
    from wsp_data.platforms.bc_policy import STAGES

    assert OPERATOR_GROUPS == tuple(OPERATORS) and POLICY_GROUPS == tuple(f"policy_{s}" for s in STAGES)
    assert len(SOURCE_GROUPS) == 8


def test_one_group_holds_all_eight_sources(rows, ds):
    assert sorted(rows["source_group"]) == sorted(SOURCE_GROUPS)
    assert len(set(rows["group_id"])) == 1 and len(set(rows["seed"])) == 1 and set(rows["task"]) == {"PickCube"}
    assert ds.num_episodes == len(rows) == 8
    for r in rows:
        ep = ds.meta.episodes[r["episode_indices"][0]]
        assert ep["wsp.role"] == "reference" and ep["wsp.seed"] == r["seed"] and ep["wsp.source"] == r["source"]
        assert bool(ep["wsp.success"]) == r["source_success"] == r["success"][0]
    expert = next(r for r in rows if r["source_group"] == "expert")
    assert expert["source_success"]  # the group's scene is one the expert solves


def test_provenance_is_honest(rows):
    kinds = {r["source_group"]: (r["source_kind"], json.loads(r["source_provenance"])) for r in rows}
    assert kinds["expert"][0] == "scripted_expert"
    for h in OPERATOR_GROUPS:
        kind, prov = kinds[h]
        assert kind == "scripted_operator" and prov["operator"] == h and prov["parameters"]
    for p in POLICY_GROUPS:
        kind, prov = kinds[p]
        assert kind == "bc_policy" and prov["stage"] == p.removeprefix("policy_") and prov["training_steps"] > 0
    steps = {g: prov["training_steps"] for g, (_, prov) in kinds.items() if g in POLICY_GROUPS}
    assert steps["policy_early"] < steps["policy_late"]


def test_sources_really_differ(rows):
    """Same scene, different executions: every pair of streams differs, and H1 (slow) outlasts H2 (fast)."""
    by = {r["source_group"]: r for r in rows}
    assert by["H1"]["steps"] > by["expert"]["steps"] > by["H2"]["steps"]


def test_every_stored_stream_replays_to_its_stored_states(rows, ds):
    from wsp_data.platforms.maniskill.env import ManiSkillPlatform

    with ManiSkillPlatform("PickCube", render=False, objects=tuple(rows[0]["objects"])) as sim:
        for r in rows:
            ep = ds.meta.episodes[r["episode_indices"][0]]
            table = ds.hf_dataset.select(range(ep["dataset_from_index"], ep["dataset_to_index"]))
            actions = np.stack([np.asarray(a, np.float32) for a in table["action"]])[:-1]
            qpos = np.stack([np.asarray(q, np.float32) for q in table["observation.state"]])
            poses = np.stack([np.asarray(p, np.float32) for p in table[OBJECT_POSES_KEY]])
            ro = sim.replay(r["seed"], actions)
            assert np.array_equal(ro.stack("qpos").astype(np.float32), qpos), r["source_group"]
            sim_poses = np.nan_to_num(ro.stack("object_poses"), nan=0.0).astype(np.float32)  # stored: unused slots 0
            assert np.array_equal(sim_poses.reshape(len(poses), MAX_OBJECTS * 7), poses), r["source_group"]
            assert ro.success == r["source_success"]


def test_action_blind_plays_back_the_groups_expert(rows, suites_release):
    """T3's canonical execution: whatever the source, an action-blind model shows the expert of the group."""
    from wsp_eval.episode import source_episode_index

    expert = next(r for r in rows if r["source_group"] == "expert")["episode_indices"][0]
    assert {source_episode_index(CONFIG, r, suites_release / CONFIG) for r in rows} == {expert}
