"""The submission contract: a real oracle submission of the tiny T1 release validates; every planted defect
is reported, by file, in one pass; the CLI never crashes on a broken submission."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from wsp_eval.baselines import write_baseline
from wsp_eval.reference import reference_frames
from wsp_eval.submission import validate
from wsp_eval.video import read_video, write_video


@pytest.fixture(scope="module")
def oracle(t1_release, tmp_path_factory):
    out = tmp_path_factory.mktemp("sub") / "oracle"
    assert write_baseline("oracle", t1_release, out, seeds=(0,)) > 0
    return out


def test_oracle_submission_is_valid_and_exact(oracle, t1_release):
    assert validate(oracle, t1_release) == []
    frames, fps = read_video(oracle / "t1_maniskill" / "episode_000001" / "seed0.mp4")
    ref = reference_frames(t1_release / "t1_maniskill", 1)
    assert fps == 20 and frames.shape == ref.shape
    assert np.abs(frames.astype(int) - ref).mean() < 1.0  # crf 0 yuv444p round trip


def test_every_planted_defect_is_reported_by_file(oracle, t1_release, tmp_path):
    import shutil

    sub = tmp_path / "broken"
    shutil.copytree(oracle, sub)
    ep = lambda i: sub / "t1_maniskill" / f"episode_{i:06d}" / "seed0.mp4"  # noqa: E731
    ep(0).unlink()                                                   # missing
    (sub / "t1_maniskill" / "notes.txt").write_text("hi")            # extra file
    ep(1).write_bytes(ep(1).read_bytes()[: ep(1).stat().st_size // 3])  # truncated
    frames = {i: read_video(ep(i))[0] for i in (2, 4, 5)}
    write_video(ep(2), frames[2][:10], 20)                           # wrong frame count
    ep(3).write_bytes(b"")                                           # zero frames
    write_video(ep(4), np.full_like(frames[4], 128), 20)             # constant video
    write_video(ep(5), frames[5], 1000)                              # absurd fps
    ep(6).unlink()
    os.symlink("/etc/hostname", ep(6))                               # link pointing outside
    meta = json.loads((sub / "submission.json").read_text())
    meta["benchmark_version"] = "9.9.9"
    (sub / "submission.json").write_text(json.dumps(meta))
    problems = [str(p) for p in validate(sub, t1_release)]
    text = "\n".join(problems)
    assert "submission.json: benchmark_version '9.9.9' does not match" in text
    # a wrong version stops before the videos: fix it and list the rest in one pass
    meta["benchmark_version"] = json.loads((oracle / "submission.json").read_text())["benchmark_version"]
    (sub / "submission.json").write_text(json.dumps(meta))
    text = "\n".join(str(p) for p in validate(sub, t1_release))
    for expected in (
        "t1_maniskill/episode_000000/seed0.mp4: missing",
        "t1_maniskill/notes.txt: unexpected file",
        "t1_maniskill/episode_000001/seed0.mp4: unreadable video",
        "t1_maniskill/episode_000002/seed0.mp4: 10 frames; the reference horizon is",
        "t1_maniskill/episode_000003/seed0.mp4: empty file (zero frames)",
        "t1_maniskill/episode_000004/seed0.mp4: constant video",
        "t1_maniskill/episode_000005/seed0.mp4: fps missing or absurd (1000.0)",
        "t1_maniskill/episode_000006/seed0.mp4: is a link (outside the submission",
    ):
        assert expected in text, f"not reported: {expected}\n{text}"
    assert len(text.splitlines()) == 9  # the 8 defects + the linked video counted missing

    r = subprocess.run([sys.executable, "-m", "wsp_eval.cli", "validate", str(sub), "--release", str(t1_release)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 1 and "Traceback" not in r.stderr and "9 problem(s)" in r.stdout

    # `wsp score` never crashes on it: a link stops it with a clear message; missing files stop it unless
    # --allow-missing, which scores every defective rollout 0 and lists it in the report
    score = [sys.executable, "-m", "wsp_eval.cli", "score", str(sub), "--release", str(t1_release), "--quiet"]
    r = subprocess.run(score + ["--out", str(tmp_path / "r1")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "is a link" in r.stderr
    ep(6).unlink()
    r = subprocess.run(score + ["--out", str(tmp_path / "r2")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "--allow-missing" in r.stderr
    r = subprocess.run(score + ["--out", str(tmp_path / "r3"), "--allow-missing"], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    report = json.loads((tmp_path / "r3" / "report.json").read_text())
    assert len(report["problems"]) == 7  # episodes 0 and 6 missing, 1 truncated, 2 short, 3 empty, 4 constant, 5 fps
    assert (tmp_path / "r3" / "report.html").is_file() and (tmp_path / "r3" / "report.md").is_file()


def test_bad_manifest(tmp_path, t1_release):
    assert [str(p) for p in validate(tmp_path / "nope", t1_release)] == [f"{tmp_path / 'nope'}: submission folder not found"]
    (tmp_path / "submission.json").write_text('{"model": "m", "seeds": [0, 0], "benchmark_version": 1}')
    text = "\n".join(str(p) for p in validate(tmp_path, t1_release))
    assert "'benchmark_version' missing or not a str" in text and "distinct non-negative integers" in text


def test_a_partially_downloaded_release_is_named_not_a_traceback(oracle, t1_release, tmp_path):
    """A release folder whose release.json lists a config that was not downloaded (users often fetch one config of
    the hub repo): validate and score name the missing file and how to proceed, and score writes no report."""
    partial = tmp_path / "partial"
    partial.mkdir()
    (partial / "release.json").write_text((t1_release / "release.json").read_text())  # t1_maniskill's folder absent
    missing = partial / "t1_maniskill" / "instances.parquet"
    assert [p.path for p in validate(oracle, partial)] == [str(missing)]
    for verb in (["validate"], ["score", "--out", str(tmp_path / "report"), "--quiet"]):
        r = subprocess.run([sys.executable, "-m", "wsp_eval.cli", *verb[:1], str(oracle), "--release", str(partial),
                            *verb[1:]], capture_output=True, text=True, timeout=300)
        assert r.returncode != 0 and "Traceback" not in r.stderr, r.stderr
        assert str(missing) in r.stdout + r.stderr and "partial download" in r.stdout + r.stderr
    assert not (tmp_path / "report" / "report.json").exists()
