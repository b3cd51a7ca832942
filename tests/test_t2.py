"""A real tiny T2 release (3 receiver–donor replays, ManiSkill, rendered, LeRobot-written): both loaders, and
every stored quantity recomputed independently from the release and the simulator: the donor stream, the
validity checks, the scorable RMFA windows and the motion mismatch."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import T2_TASKS as TASKS
from conftest import assert_source_episodes, build_tiny, instance_rows, open_lerobot, release_files

from wsp_data.builders.t2 import (
    MISMATCH_POINTS, TYPICAL_TRAJECTORIES, arm_blocked, motion_mismatch, object_flung, replay_problem,
    time_normalised,
)
from wsp_data.platforms import BLOCK_STEPS, kit
from wsp_data.schema import FPS, MAX_OBJECTS, OBJECT_POSES_KEY, SEED_BASE, VIDEO_KEY
from wsp_eval.reference import object_poses, reference_masks



@pytest.fixture(scope="module")
def release(suites_release):
    return suites_release


@pytest.fixture(scope="module")
def rows(release):
    return instance_rows(release, "t2_maniskill")


@pytest.fixture(scope="module")
def episodes(release, rows):
    """Per instance, its reference episode as arrays decoded from the LeRobot dataset."""
    ds = open_lerobot(release, "t2_maniskill")
    assert_source_episodes(ds, rows)
    out = []
    for r in rows:
        (idx,) = r["episode_indices"]
        ep = ds.meta.episodes[idx]
        assert ep["wsp.role"] == "reference" and ep["wsp.task"] == r["task"] and ep["wsp.seed"] == r["seed"]
        assert json.loads(ep["wsp.intervention"]) == {"donor_task": r["donor_task"], "donor_seed": r["donor_seed"]}
        frames = [ds[i] for i in range(ep["dataset_from_index"], ep["dataset_to_index"])]

        def stack(key, frames=frames):
            return np.stack([f[key].numpy() for f in frames])
        out.append({
            "rgb": (stack(VIDEO_KEY).transpose(0, 2, 3, 1) * 255).round().astype(np.uint8),
            "labels": reference_masks(ds.root, idx),
            "actions": stack("action")[:-1],  # the last frame repeats the last action, never executed
            "qpos": stack("observation.state"), "tcp": stack("observation.ee_pose"),
            "objects": object_poses(stack(OBJECT_POSES_KEY)),
        })
    return out


@pytest.fixture(scope="module")
def experts():
    from wsp_data.platforms.maniskill.experts import ExpertSource

    sources = {t: ExpertSource(t) for t in TASKS}
    yield sources
    for s in sources.values():
        s.close()


def test_rows_load_and_pair_different_tasks(rows, release):
    report = json.loads((release / "t2_maniskill" / "build_report.json").read_text())
    assert len(rows) == report["kept"] >= 2
    for r in rows:
        assert r["roles"] == ["reference"]
        assert r["donor_task"] in TASKS and r["donor_task"] != r["task"]
        assert r["source"] == f"scripted_expert (donor: {r['donor_task']})"
        assert r["donor_seed"] != r["seed"]
        assert 1 <= r["active_windows"] <= r["num_windows"]
        assert r["mismatch"] > 0


def test_stored_stream_is_the_donor_expert_stream(rows, episodes, experts):
    for r, ep in zip(rows, episodes):
        donor = experts[r["donor_task"]].trajectory(r["donor_seed"])
        assert donor is not None and np.array_equal(ep["actions"], donor)


def test_stored_states_pass_validity(rows, episodes, experts):
    for r, ep in zip(rows, episodes):
        qlimits = experts[r["task"]].replayer.robot.get_qlimits()[0].numpy()
        assert replay_problem(ep["qpos"], ep["tcp"], ep["objects"], ep["actions"], qlimits) is None
        # the same states with the arm frozen from mid-rollout, or an object knocked 6 cm in one frame, fail
        frozen = ep["qpos"].copy()
        frozen[len(frozen) // 2:, :7] = frozen[len(frozen) // 2, :7] + 0.2
        assert arm_blocked(frozen, ep["actions"]) == (len(frozen) // 2 >= BLOCK_STEPS)
        knocked = ep["objects"].copy()
        knocked[len(knocked) // 2:, 0, 0] += 0.06  # 1.2 m/s for one frame
        assert replay_problem(ep["qpos"], ep["tcp"], knocked, ep["actions"], qlimits) == "object_flung"


def test_every_instance_has_scorable_robot_motion(rows, episodes):
    """Recomputed from the stored video (h264 crf 0) and PNG label masks, not from the build's frames."""
    from wsp_eval.flow import active_pixels_per_window, reference_flows

    for r, ep in zip(rows, episodes):
        assert set(np.unique(ep["labels"])) <= {0, 1, 2}
        active = active_pixels_per_window(*reference_flows(ep["rgb"], ep["labels"], FPS))
        assert len(active) == r["num_windows"]
        assert (active > 0).sum() >= 1


def test_mismatch_recomputes(rows, episodes, experts):
    """Independent recomputation: the receiver's first 8 verified expert streams on training seeds,
    each resampled to 50 points of normalised time, averaged; RMS distance to the stored donor arm stream."""
    typical = {}
    for task in {r["task"] for r in rows}:
        streams, seed = [], SEED_BASE["train"]
        while len(streams) < TYPICAL_TRAJECTORIES:
            if (a := experts[task].trajectory(seed)) is not None:
                u = np.arange(len(a)) / (len(a) - 1)
                streams.append([np.interp(np.linspace(0, 1, MISMATCH_POINTS), u, a[:, j]) for j in range(7)])
            seed += 1
        typical[task] = np.mean(streams, axis=0).T
    for r, ep in zip(rows, episodes):
        d = np.array([np.interp(np.linspace(0, 1, MISMATCH_POINTS), np.linspace(0, 1, len(ep["actions"])),
                                ep["actions"][:, j]) for j in range(7)]).T
        assert r["mismatch"] == pytest.approx(np.sqrt(np.mean((d - typical[r["task"]]) ** 2)), rel=1e-9)


def test_time_normalisation_and_mismatch_worked_examples():
    ramp = np.zeros((11, 8), dtype=np.float32)
    ramp[:, :7] = np.linspace(0, 1, 11)[:, None] * np.arange(1, 8)  # joint j goes 0 → j + 1
    ramp[:, 7] = 5.0  # the gripper is ignored
    out = time_normalised(ramp, kit("maniskill"), 5)
    assert np.allclose(out, np.linspace(0, 1, 5)[:, None] * np.arange(1, 8))
    assert motion_mismatch(ramp, out, kit("maniskill")) == pytest.approx(0.0, abs=1e-12)
    assert motion_mismatch(ramp, out + 0.1, kit("maniskill")) == pytest.approx(0.1)
    with pytest.raises(ValueError):
        time_normalised(ramp[:1], kit("maniskill"))


def test_collision_checks_on_hand_built_states():
    actions = np.zeros((30, 8))
    qpos = np.zeros((31, 9))
    assert not arm_blocked(qpos, actions)
    qpos[11:20, 3] = 0.2  # lags 0.2 rad for 9 steps: transient
    assert not arm_blocked(qpos, actions)
    qpos[11:21, 3] = 0.2  # 10 steps: blocked
    assert arm_blocked(qpos, actions)
    poses = np.full((31, MAX_OBJECTS, 7), np.nan)
    poses[:, 0] = 0.0
    poses[:, 0, 2] = np.linspace(0, 0.5, 31)  # falls/rises at 0.33 m/s vertically only
    assert not object_flung(poses)
    poses[15:, 0, 1] += 0.051  # 1.02 m/s horizontally for one frame
    assert object_flung(poses)


def test_a_bounded_rig_cache_gives_the_same_config(release, tmp_path_factory, monkeypatch):
    """T2 keeps every task's typical stream apart from its rig, so a platform's `rigs_per_worker` bounds it
    (to at least 2: one attempt holds its receiver's and its donor's rig). Bounded to 1 here (so 2 rigs over
    three tasks: rigs are closed and made again mid-build), the config's files are those of the shared
    release's unbounded build."""
    from wsp_data.platforms.maniskill.kit import ManiSkillKit

    monkeypatch.setattr(ManiSkillKit, "rigs_per_worker", 1)
    out = build_tiny(tmp_path_factory, "t2", 3, TASKS)
    ours = {k: v for k, v in release_files(out).items() if k.startswith("t2_maniskill/")}
    assert ours and ours == {k: v for k, v in release_files(release).items() if k.startswith("t2_maniskill/")}
