"""`generate` runs a model over the tiny real T1 release: the model sees the reference frame 0 and the
episode's own action stream; its output becomes a valid submission, a killed run resumes, and bad output
or a bad model name is reported by episode."""

from __future__ import annotations

import json
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from wsp_eval.generate import GenerateError, check_frames, generate, load_model
from wsp_eval.reference import reference_frames
from wsp_eval.submission import validate
from wsp_eval.video import read_video

CONFIG = "t1_maniskill"
PIXELS_PER_RAD = 20.0  # the toy model's horizontal shift per radian of summed joint-0 target


def shift_model(first_frame: np.ndarray, actions: np.ndarray, fps: float, seed: int) -> np.ndarray:
    """Frame t: the first frame rolled sideways by round(20 · cumsum(action[:, 0])[t]) + seed pixels."""
    shifts = np.rint(PIXELS_PER_RAD * np.cumsum(actions[:, 0])).astype(int) + seed
    return np.stack([np.roll(first_frame, s, axis=1) for s in shifts])


def episode_count(release) -> int:
    ids = pq.read_table(release / CONFIG / "instances.parquet", columns=["episode_ids"]).column(0).to_pylist()
    return sum(map(len, ids))


def test_model_output_becomes_a_valid_submission(t1_release, tmp_path):
    calls = []

    def model(first_frame, actions, fps, seed):
        calls.append((first_frame, actions, fps, seed))
        return shift_model(first_frame, actions, fps, seed)

    result = generate(model, t1_release, tmp_path, seeds=(0, 1), name="shift", progress=False)
    assert (result.written, result.skipped) == (2 * episode_count(t1_release), 0) == (len(calls), 0)
    assert validate(tmp_path, t1_release) == []
    meta = json.loads((tmp_path / "submission.json").read_text())
    assert meta["model"] == "shift" and meta["seeds"] == [0, 1] and meta["configs"] == [CONFIG]
    assert meta["hardware"] and meta["generation_seconds"] >= 0

    first_frame, actions, fps, seed = calls[0]  # episode 0, seed 0
    data = pq.read_table(t1_release / CONFIG / "data", columns=["frame_index", "action"],
                         filters=[("episode_index", "==", 0)]).sort_by("frame_index")
    assert actions.dtype == np.float32 and np.array_equal(actions, np.stack(data.column("action").to_numpy()))
    assert np.array_equal(first_frame, reference_frames(t1_release / CONFIG, 0)[0]) and (fps, seed) == (20, 0)
    video, _ = read_video(tmp_path / CONFIG / "episode_000000" / "seed0.mp4")
    assert np.abs(video.astype(int) - shift_model(*calls[0])).mean() < 1.0


def test_killed_run_resumes(t1_release, tmp_path):
    done = []

    def dies_after_two(*args):
        if len(done) == 2:
            raise RuntimeError("killed")
        done.append(1)
        return shift_model(*args)

    with pytest.raises(RuntimeError, match="killed") as info:
        generate(dies_after_two, t1_release, tmp_path, seeds=(0,), name="shift", progress=False)
    assert "while generating t1_maniskill/episode_000002/seed0" in info.value.__notes__
    assert len(list(tmp_path.rglob("*.mp4"))) == 2 and not list(tmp_path.rglob(".*"))
    seconds = json.loads((tmp_path / "submission.json").read_text())["generation_seconds"]

    result = generate(shift_model, t1_release, tmp_path, seeds=(0,), name="shift", progress=False)
    assert (result.written, result.skipped) == (episode_count(t1_release) - 2, 2)
    assert validate(tmp_path, t1_release) == []
    assert json.loads((tmp_path / "submission.json").read_text())["generation_seconds"] >= seconds
    with pytest.raises(GenerateError, match="holds a submission of model 'shift', not 'other'"):
        generate(shift_model, t1_release, tmp_path, seeds=(0,), name="other", progress=False)


@pytest.mark.parametrize("bad, message", [
    (lambda f, a, fps, s: shift_model(f, a, fps, s)[:-1], r"frames; the reference horizon is"),
    (lambda f, a, fps, s: np.full((len(a), *f.shape), np.nan), r"NaN"),
    (lambda f, a, fps, s: f, r"frames of shape \(128, 128, 3\); expected \(N, H, W, 3\)"),
    (lambda f, a, fps, s: np.zeros((len(a), 256, 256, 3), np.uint8),
     r"frames of 256×256 pixels; the reference frame is 128×128: return frames at its resolution"),
])
def test_bad_output_names_the_episode(t1_release, tmp_path, bad, message):
    with pytest.raises(GenerateError, match=rf"^t1_maniskill/episode_000000/seed0: .*{message}"):
        generate(bad, t1_release, tmp_path, seeds=(0,), name="bad", progress=False)
    assert not list(tmp_path.rglob("*.mp4"))


def test_check_frames_converts_numbers():
    frames = np.full((2, 4, 4, 3), 100.4)
    assert check_frames(frames, 2, "x").dtype == np.uint8 and (check_frames(frames, 2, "x") == 100).all()
    with pytest.raises(GenerateError, match=r"x: values span \[-1.0, 100.4\], outside \[0, 255\]"):
        check_frames(np.concatenate([frames, np.full((1, 4, 4, 3), -1.0)])[1:], 2, "x")


def test_bad_action_key_and_configs(t1_release, tmp_path):
    with pytest.raises(GenerateError, match=r"no column 'action.joint'; action columns: action, action.ee"):
        generate(shift_model, t1_release, tmp_path, seeds=(0,), name="m", action_key="action.joint", progress=False)
    with pytest.raises(GenerateError, match="not among its scored configs"):
        generate(shift_model, t1_release, tmp_path, seeds=(0,), configs=["t9_x"], name="m", progress=False)


def test_load_model(tmp_path, monkeypatch):
    (tmp_path / "toy_wm.py").write_text("def generate(first_frame, actions, fps, seed):\n    return None\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    assert load_model("toy_wm:generate").__module__ == "toy_wm"  # a model file in the current directory
    assert load_model("numpy:zeros") is np.zeros
    assert load_model("numpy:random.default_rng") is np.random.default_rng
    for spec, message in [("no.such:thing", "cannot import module 'no.such'"),
                          ("numpy", "expected 'module:callable'"), ("numpy:no_such", "has no attribute 'no_such'"),
                          ("math:pi", "'pi' is a float, not callable")]:
        with pytest.raises(GenerateError, match=message):
            load_model(spec)


class BatchedShift:
    """The shift model behind the batched call, recording each batch it is sent."""
    wsp_batch_size = 3

    def __init__(self, fail_after: int | None = None):
        self.batches: list[list] = []
        self.fail_after = fail_after

    def __call__(self, requests):
        if self.fail_after is not None and len(self.batches) == self.fail_after:
            raise RuntimeError("killed")
        self.batches.append(requests)
        return [shift_model(*r) for r in requests]


def test_batched_model_writes_the_same_submission(t1_release, tmp_path):
    generate(shift_model, t1_release, tmp_path / "single", seeds=(0, 1), name="shift", progress=False)
    model = BatchedShift()
    result = generate(model, t1_release, tmp_path / "batched", seeds=(0, 1), name="shift", progress=False)
    n = 2 * episode_count(t1_release)
    assert result.written == n and [len(b) for b in model.batches] == [3] * (n // 3) + ([n % 3] if n % 3 else [])
    assert model.batches[0][1].seed == 1 and model.batches[0][0].fps == 20  # episode 0 seed 0, then seed 1
    for video in (tmp_path / "single").rglob("*.mp4"):  # byte-identical videos, either interface
        assert video.read_bytes() == (tmp_path / "batched" / video.relative_to(tmp_path / "single")).read_bytes()
    assert validate(tmp_path / "batched", t1_release) == []


def test_killed_batched_run_resumes_and_bad_batches_are_named(t1_release, tmp_path):
    with pytest.raises(RuntimeError, match="killed"):
        generate(BatchedShift(fail_after=1), t1_release, tmp_path, seeds=(0,), name="shift", progress=False)
    assert len(list(tmp_path.rglob("*.mp4"))) == 3  # the first batch; the batch in flight is lost, no partial file
    result = generate(BatchedShift(), t1_release, tmp_path, seeds=(0,), name="shift", progress=False)
    assert (result.written, result.skipped) == (episode_count(t1_release) - 3, 3)
    assert validate(tmp_path, t1_release) == []

    class ShortBatch(BatchedShift):
        def __call__(self, requests):
            return super().__call__(requests)[:-1]

    with pytest.raises(GenerateError, match=r"asked for 3 video\(s\), returned 2 item\(s\)"):
        generate(ShortBatch(), t1_release, tmp_path / "short", seeds=(0,), name="m", progress=False)
    bad = BatchedShift()
    bad.wsp_batch_size = 0
    with pytest.raises(GenerateError, match="wsp_batch_size 0: expected an integer from 1 to"):
        generate(bad, t1_release, tmp_path / "bad", seeds=(0,), name="m", progress=False)


def test_the_readme_example_adapter_runs(t1_release, tmp_path, monkeypatch):
    """docs/example_adapter.py (shown in the README) loads by name and writes a valid submission."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    monkeypatch.chdir(root)
    model = load_model("docs.example_adapter:model")
    assert model.wsp_batch_size == 8
    generate(model, t1_release, tmp_path, seeds=(0,), name="example", progress=False)
    assert validate(tmp_path, t1_release) == []
    assert (root / "docs" / "example_adapter.py").read_text().strip() in (root / "README.md").read_text()
