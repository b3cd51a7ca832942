"""The reference world model (`wsp_models.reference`): training is deterministic, resumes to the same weights and
keeps snapshots without changing the run; the shipped checkpoints generate through `wsp generate --model
reference` a submission that validates, is the same for every run and seed, and answers actions (T1 above the
static baseline's 0)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from wsp_models.reference import train as train_mod  # noqa: E402
from wsp_models.reference.model import CHECKPOINTS, ReferenceModel  # noqa: E402

WSP = str(Path(sys.executable).with_name("wsp"))
TINY = train_mod.Recipe(steps=4, batch=2, threads=1, size=64)


def _weights(path: Path) -> dict:
    return torch.load(path, weights_only=False)["state_dict"]


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_training_is_deterministic_and_resumes(libero_release, tmp_path, monkeypatch):
    monkeypatch.setattr(train_mod, "SAVE_EVERY", 2)
    monkeypatch.setattr(train_mod, "VAL_EVERY", 2)
    first = _weights(train_mod.train(libero_release, "train_libero", tmp_path / "a", TINY, progress=False))
    second = _weights(train_mod.train(libero_release, "train_libero", tmp_path / "b", TINY, progress=False,
                                      snapshots=(2,)))
    assert _same(first, second)  # keeping a snapshot does not change the run
    snapshot = torch.load(tmp_path / "b" / "step2" / "libero.pt", weights_only=False)
    assert snapshot["record"]["step"] == 2 and not _same(snapshot["state_dict"], first)
    assert ReferenceModel(tmp_path / "b" / "step2", threads=1).wsp_info["reference_model"]["libero"]["steps"] == 2
    with pytest.raises(ValueError, match="multiple of 2"):
        train_mod.train(libero_release, "train_libero", tmp_path / "d", TINY, progress=False, snapshots=(3,))

    calls = 0
    real = train_mod._sample

    def dies_at_step_3(*args):  # call 1 draws the validation set, call k + 1 the batch of step k
        nonlocal calls
        calls += 1
        if calls == 4:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(train_mod, "_sample", dies_at_step_3)
    with pytest.raises(KeyboardInterrupt):
        train_mod.train(libero_release, "train_libero", tmp_path / "c", TINY, progress=False)
    assert (tmp_path / "c" / ".train_state.pt").is_file()  # saved at step 2
    monkeypatch.setattr(train_mod, "_sample", real)
    resumed = train_mod.train(libero_release, "train_libero", tmp_path / "c", TINY, progress=False)
    assert _same(_weights(resumed), first)
    history = json.loads(resumed.with_suffix(".history.json").read_text())
    assert [s for s, _ in history["val"]] == [2, 4] and np.isfinite([v for _, v in history["val"]]).all()
    assert not (tmp_path / "c" / ".train_state.pt").exists()


def test_shipped_checkpoints_are_small_and_named():
    shipped = sorted(p.stem for p in CHECKPOINTS.glob("*.pt"))
    assert "maniskill" in shipped
    for p in CHECKPOINTS.glob("*.pt"):
        assert p.stat().st_size <= 50e6
        assert torch.load(p, weights_only=False)["record"]["platform"] == p.stem


@pytest.fixture(scope="module")
def submission(t1_release, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("reference") / "sub"
    subprocess.run([WSP, "generate", "--model", "reference", "--release", str(t1_release), "--out", str(out),
                    "--seeds", "0", "1", "--quiet"], check=True)
    return out


def test_generated_submission_validates_and_is_deterministic(submission, t1_release, tmp_path):
    from wsp_eval.video import read_video

    subprocess.run([WSP, "validate", str(submission), "--release", str(t1_release)], check=True)
    meta = json.loads((submission / "submission.json").read_text())
    assert meta["model"] == "reference" and meta["generation_seconds"] > 0
    assert meta["model_info"]["reference_model"]["maniskill"]["parameters"] > 0
    videos = sorted(submission.glob("t1_maniskill/*/seed0.mp4"))
    assert videos
    again = tmp_path / "again"
    subprocess.run([WSP, "generate", "--model", "reference", "--release", str(t1_release), "--out", str(again),
                    "--seeds", "0", "--quiet"], check=True)
    for v in videos:
        a = read_video(v)[0]
        assert np.array_equal(a, read_video(v.with_name("seed1.mp4"))[0])  # the seed does not change the output
        assert np.array_equal(a, read_video(again / v.relative_to(submission))[0])  # nor does the run


def test_reference_model_answers_actions(submission, t1_release, tmp_path):
    """T1 needs D(ĝ⁰,ĝˢ) < D(ĝ⁰,ĝˡ), both > 0: the static and action-blind baselines score exactly 0."""
    subprocess.run([WSP, "score", str(submission), "--release", str(t1_release), "--out", str(tmp_path / "rep"),
                    "--quiet"], check=True, stdout=subprocess.DEVNULL)
    report = json.loads((tmp_path / "rep" / "report.json").read_text())
    assert report["platforms"]["maniskill"]["suites"]["t1"]["score"] > 0
