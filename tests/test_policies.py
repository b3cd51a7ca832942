"""T3 policy sources: the shipped checkpoints load, act deterministically, differ by stage, and a closed-loop
policy stream replays open-loop to the very same states."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wsp_data.platforms.bc_policy import STAGES, TRAINING_CONFIG, PolicyCheckpointMissing, closed_loop_success
from wsp_data.platforms.maniskill.t3 import CHECKPOINT_DIR, T3_TASKS, PolicySource, checkpoint_path, feature_names


@pytest.mark.parametrize("task", T3_TASKS)
def test_checkpoints_load_with_provenance(task):
    config = json.loads((CHECKPOINT_DIR / TRAINING_CONFIG).read_text())["tasks"][task]
    steps = {}
    for stage in STAGES:
        path = checkpoint_path(task, stage)
        assert path.stat().st_size < 1_000_000
        src = PolicySource(task, stage)
        prov = src.provenance
        assert prov["task"] == task and prov["stage"] == stage
        assert prov["checkpoint_sha256"] == config["checkpoint_sha256"][stage]
        assert prov["training_steps"] == config["stage_steps"][stage]
        assert prov["success_rate"] == config["success"][stage]["rate"]
        assert prov["training_config"]["features"] == feature_names(task)
        assert max(prov["training_config"]["demo_seeds"]) < 1_000_000  # training seeds only
        steps[stage] = prov["training_steps"]
        src.close()
    assert steps["early"] < steps["late"]


def test_missing_checkpoint_names_path_and_script(tmp_path):
    with pytest.raises(FileNotFoundError) as err:
        PolicySource("PickCube", "late", checkpoint_dir=tmp_path)
    assert isinstance(err.value, PolicyCheckpointMissing)
    msg = str(err.value)
    assert str(tmp_path / "PickCube_late.pt") in msg and "scripts/train_bc_policies.py --platform maniskill" in msg
    with pytest.raises(KeyError):
        PolicySource("PickCube", "middle")
    with pytest.raises(KeyError):
        PolicySource("StackCube", "late")


def test_policy_stream_is_deterministic_and_replays_to_its_states():
    from wsp_data.platforms.maniskill.env import ManiSkillPlatform
    from wsp_data.platforms.maniskill.experts import task_spec

    task, seed = "PickCube", 950_000  # a training-range seed no checkpoint was trained or evaluated on
    late, early = PolicySource(task, "late"), PolicySource(task, "early")
    try:
        actions, success = late.trajectory(seed, max_steps=60)
        states = late.observations
        assert actions.dtype == np.float32 and actions.shape[1] == 8 and len(states) == len(actions) + 1
        assert np.isfinite(actions).all() and set(np.unique(actions[:, 7])) <= {-1.0, 1.0}
        lim = np.asarray(late.meta["arm_limits"])
        assert (actions[:, :7] >= lim[:, 0] - 1e-6).all() and (actions[:, :7] <= lim[:, 1] + 1e-6).all()

        # act is a pure function of (observation, step, goal): same input → identical action
        for t in (0, len(actions) // 2):
            a1, a2 = late.act(states[t], t), late.act(states[t], t)
            assert np.array_equal(a1, a2) and np.array_equal(a1, actions[t])
        # early and late checkpoints are different policies
        assert any(not np.array_equal(early.act(states[t], t, goal=late.goal), actions[t])
                   for t in range(0, len(actions), 5))

        # open-loop replay of the recorded stream in another env gives the same states
        with ManiSkillPlatform(task, render=False, objects=task_spec(task).objects) as p:
            ro = p.replay(seed, actions)
        assert np.array_equal(ro.stack("qpos"), np.stack([o.qpos for o in states]))
        assert np.array_equal(ro.stack("object_poses"), np.stack([o.object_poses for o in states]),
                              equal_nan=True)
        assert ro.success == success

        # running the policy again reproduces the stream exactly
        again, success_again = late.trajectory(seed, max_steps=60)
        assert np.array_equal(again, actions) and success_again == success
    finally:
        late.close()
        early.close()


def test_closed_loop_success_summarises_each_rollout():
    """What the training scripts record as a checkpoint's success (`closed_loop_success`) is the rollouts'
    own: per seed, the stream and success `trajectory` gives, and the source is closed after."""
    task, seeds = "PushCube", [950_001]  # a training-range seed no checkpoint was evaluated on
    summary, streams = closed_loop_success(PolicySource(task, "late"), seeds)
    with PolicySource(task, "late") as src:
        runs = [src.trajectory(s) for s in seeds]
        budget = src.default_max_steps()
    assert all(np.array_equal(a, b) for a, (b, _) in zip(streams, runs))
    (stream, ok), = runs
    assert summary == {"rate": float(ok), "successes": int(ok), "seeds": 1, "seed_range": seeds * 2,
                       "mean_steps": float(len(stream)), "max_steps": budget}
