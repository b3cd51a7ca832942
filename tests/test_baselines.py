"""Calibration baselines on the tiny real T1 release: every one writes a valid submission, resumably and
deterministically, and each degraded oracle degrades what it says it does."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pyarrow.parquet as pq
import pytest

from wsp_eval.baselines import (BASELINES, LAG_SECONDS, BaselineError, EpisodeContext, paired_regions,
                                fit_length, write_baseline)
from wsp_eval.episode import source_episode_index
from wsp_eval.reference import reference_frames
from wsp_eval.submission import validate
from wsp_eval.video import read_video

CONFIG = "t1_maniskill"


@pytest.fixture(scope="module")
def row(t1_release) -> dict:
    return pq.read_table(t1_release / CONFIG / "instances.parquet").to_pylist()[0]


def context(release, row, role: str, seed: int = 0, config: str = CONFIG) -> EpisodeContext:
    index = row["episode_indices"][row["roles"].index(role)]
    return EpisodeContext(release, config, row, role, index, float(row["fps"]), seed)


@pytest.fixture(scope="module")
def small(t1_release, row) -> EpisodeContext:
    return context(t1_release, row, "small")


def test_every_baseline_writes_a_valid_submission(t1_release, tmp_path):
    for name in BASELINES:
        out = tmp_path / name
        assert write_baseline(name, t1_release, out, seeds=(0,)) > 0
        assert validate(out, t1_release) == [], name
        assert json.loads((out / "submission.json").read_text())["model"] == f"baseline:{name}"
        assert BASELINES[name].__doc__ and "\n" not in BASELINES[name].__doc__
    with pytest.raises(KeyError, match="unknown baseline 'nope'; known: oracle"):
        write_baseline("nope", t1_release, tmp_path / "nope")


def test_resumes_and_is_deterministic(t1_release, tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    n = write_baseline("noise", t1_release, first, seeds=(0,))
    video = first / CONFIG / "episode_000001" / "seed0.mp4"
    video.unlink()
    assert write_baseline("noise", t1_release, first, seeds=(0,)) == 1  # only the missing one
    assert not list(first.rglob(".*"))  # no temp files left behind
    assert write_baseline("noise", t1_release, second, seeds=(0,)) == n
    assert np.array_equal(read_video(video)[0], read_video(second / video.relative_to(first))[0])


def test_noise_depends_on_seed_only(small):
    a, b = BASELINES["noise"](small), BASELINES["noise"](replace(small, seed=1))
    assert np.array_equal(a, BASELINES["noise"](small)) and not np.array_equal(a, b)
    assert 8 < np.std(a.astype(float) - small.frames()) < 12


def test_action_blind_shows_the_original_rollout(t1_release, row):
    original = reference_frames(t1_release / CONFIG, row["episode_indices"][row["roles"].index("original")])
    for role in ("small", "large"):
        ctx = context(t1_release, row, role)
        frames = BASELINES["action_blind"](ctx)
        assert frames.shape == ctx.frames().shape
        assert np.array_equal(frames, fit_length(original, ctx.num_frames))
        assert not np.array_equal(frames, ctx.frames())


def test_fit_length_truncates_or_pads_with_the_last_frame():
    frames = np.arange(4)[:, None, None, None] * np.ones((1, 2, 2, 3), np.uint8)
    assert fit_length(frames, 2)[:, 0, 0, 0].tolist() == [0, 1]
    assert fit_length(frames, 6)[:, 0, 0, 0].tolist() == [0, 1, 2, 3, 3, 3]


def test_lag_blur_static(small):
    ref, shift = small.frames(), int(round(LAG_SECONDS * small.fps))
    lagged = BASELINES["lag"](small)
    assert shift == 5 and lagged.shape == ref.shape
    assert np.array_equal(lagged[shift:], ref[:-shift]) and (lagged[:shift] == ref[0]).all()
    blurred = BASELINES["blur"](small).astype(float)
    assert np.abs(np.diff(blurred, axis=2)).mean() < 0.5 * np.abs(np.diff(ref.astype(float), axis=2)).mean()
    assert (BASELINES["static"](small) == ref[0]).all()


def test_robot_and_background_corruption_change_equal_pixel_counts(small):
    ref, robot = small.frames(), small.masks() > 0
    changed = {name: (BASELINES[name](small) != ref).any(axis=-1) for name in ("robot_corrupt", "background_corrupt")}
    per_frame = robot.sum(axis=(1, 2))
    assert per_frame.min() > 0
    assert np.array_equal(changed["robot_corrupt"], robot)  # every robot pixel, nothing else
    assert np.array_equal(changed["background_corrupt"].sum(axis=(1, 2)), per_frame)
    assert not (changed["background_corrupt"] & robot).any()


def test_missing_source_rollouts_are_named(t1_release, row):
    assert source_episode_index(CONFIG, row) == row["episode_indices"][row["roles"].index("original")]
    assert source_episode_index("t4_maniskill", {**row, "source_episode_index": 7}) == 7
    fake = context(t1_release, row, "small", config="t4_maniskill")  # only the config name differs
    with pytest.raises(BaselineError, match=r"t4_maniskill: the release has no source rollouts"):
        BASELINES["action_blind"](fake)


def test_background_region_is_the_robot_shape_moved_aside():
    robot = np.zeros((1, 6, 8), bool)
    robot[0, 1:4, 2:4] = True
    fg, bg = paired_regions(robot)
    assert np.array_equal(fg, robot) and np.array_equal(bg, np.roll(robot, 4, axis=2))  # no overlap at half the width


def test_a_robot_over_half_the_frame_is_capped_to_the_background_area():
    robot = np.tile(np.arange(6) < 4, (1, 6, 1))  # 24 of 36 pixels: only 12 background pixels exist
    fg, bg = paired_regions(robot)
    assert fg.sum() == bg.sum() == 12
    assert not (fg & ~robot).any() and np.array_equal(bg, ~robot)
