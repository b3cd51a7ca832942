"""The release as published (`wsp_eval.integrity`) and one writer per output folder (`wsp_eval.folder_lock`), on a
copy of the real tiny T1 release: a byte changed in any file scoring reads stops `wsp score` and `wsp validate`
with that file's name before any score is written; the memo makes a second verification hash nothing; a second
process into a folder in use stops naming the first, and a killed holder's lock is taken over."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from wsp_eval import integrity
from wsp_eval.baselines import write_baseline
from wsp_eval.folder_lock import LOCK_NAME
from wsp_eval.leaderboard import build as leaderboard
from wsp_eval.release_format import RELEASE_JSON
from wsp_eval.score import ScoreError, score_submission

CONFIG = "t1_maniskill"


@pytest.fixture(scope="module")
def pristine(t1_release, tmp_path_factory) -> tuple[Path, Path, dict]:
    """A private copy of the T1 release, an oracle submission of one seed and its report."""
    root = tmp_path_factory.mktemp("integrity")
    release = Path(shutil.copytree(t1_release, root / "worldsimprobe", ignore=shutil.ignore_patterns(".cache")))
    sub = root / "oracle"
    write_baseline("oracle", release, sub, seeds=(0,))
    report = score_submission(sub, release, root / "report", progress=False)
    return release, sub, report


@pytest.fixture
def release(pristine, tmp_path) -> Path:
    """A fresh copy of the pristine release for a test to damage."""
    return Path(shutil.copytree(pristine[0], tmp_path / "worldsimprobe", ignore=shutil.ignore_patterns(".cache")))


def _flip_a_byte(path: Path, at: int | None = None) -> None:
    data = bytearray(path.read_bytes())
    k = len(data) // 2 if at is None else at
    data[k] ^= 0x01
    path.write_bytes(bytes(data))


def _files(release: Path, config: str = CONFIG) -> list[str]:
    return sorted(integrity.config_files(json.loads((release / RELEASE_JSON).read_text()), config))


def test_the_untouched_release_verifies_and_its_report_names_each_config_by_content(pristine):
    release, _, report = pristine
    prints = integrity.verify(release)
    assert report["release"]["configs"] == {CONFIG: {"fingerprint": prints[CONFIG]}}
    listed = integrity.config_files(json.loads((release / RELEASE_JSON).read_text()), CONFIG)
    assert prints[CONFIG] == integrity.fingerprint({p: integrity.sha256(release / p) for p in listed})


@pytest.mark.parametrize("kind", ["instances.parquet", "masks.parquet", "videos/", "data/", "meta/info.json"])
def test_a_byte_changed_in_any_file_scoring_reads_stops_score_and_validate_with_its_name(pristine, release, kind,
                                                                                         tmp_path):
    """The issue's case is `instances.parquet` (every r_star changed: the oracle's T1 fell from 99.9 to 52.3,
    silently); one flipped byte in the middle of each kind of file a scoring reads must be caught as well."""
    target = next(p for p in _files(release) if p.startswith(f"{CONFIG}/{kind}"))
    _flip_a_byte(release / target)
    out = tmp_path / "report"
    with pytest.raises(ScoreError) as e:
        score_submission(pristine[1], release, out, progress=False)
    message = str(e.value)
    assert str(release / target) in message and "release.json lists" in message
    assert f"re-download config {CONFIG}" in message and "wsp build --platform maniskill --suite t1" in message
    assert not (out / "report.json").exists() and not (out / "cache").exists()  # nothing scored, nothing written
    run = subprocess.run([sys.executable, "-m", "wsp_eval.cli", "validate", str(pristine[1]), "--release",
                          str(release)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 1 and str(release / target) in run.stdout and "Traceback" not in run.stderr


def test_changed_r_star_is_refused_and_the_repaired_file_scores_as_before(pristine, release, tmp_path):
    """The issue's own tampering: every `r_star` set to 0.99 (the file no longer matching release.json)."""
    path = release / CONFIG / "instances.parquet"
    good = path.read_bytes()
    table = pq.read_table(path)
    pq.write_table(table.set_column(table.schema.get_field_index("r_star"), "r_star",
                                    [[0.99] * table.num_rows]), path)
    with pytest.raises(ScoreError, match="instances.parquet"):
        score_submission(pristine[1], release, tmp_path / "tampered", progress=False)
    path.write_bytes(good)
    again = score_submission(pristine[1], release, tmp_path / "repaired", progress=False)
    assert again["platforms"] == pristine[2]["platforms"]


def test_a_file_is_hashed_once_and_a_change_with_its_stamp_is_seen(release, monkeypatch):
    calls = []
    real = integrity.sha256
    monkeypatch.setattr(integrity, "sha256", lambda p: calls.append(p) or real(p))
    integrity.verify(release)
    first = len(calls)
    assert first == len(_files(release))  # every listed file of the config, each once
    integrity.verify(release)
    assert len(calls) == first  # remembered by (size, mtime, inode): the second run hashes nothing
    target = release / _files(release)[0]
    _flip_a_byte(target, at=0)  # same size; a new mtime
    with pytest.raises(integrity.IntegrityError, match=str(target)):
        integrity.verify(release)
    assert len(calls) == first + 1  # only the changed file was hashed again


def test_verify_names_missing_and_unlisted_files(release):
    gone = release / _files(release)[-1]
    gone.unlink()
    (release / CONFIG / "meta" / "extra.json").write_text("{}")
    run = subprocess.run([sys.executable, "-m", "wsp_eval.cli", "verify", str(release), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 1, run.stderr
    assert f"{gone}: missing" in run.stdout and "meta/extra.json: not listed in release.json" in run.stdout
    assert f"fix: re-download config {CONFIG}" in run.stdout
    (release / CONFIG / "meta" / "extra.json").unlink()
    with pytest.raises(integrity.IntegrityError, match="missing"):
        integrity.verify(release)


def test_the_leaderboard_keeps_reports_of_differing_release_files_apart(pristine, tmp_path):
    _, _, report = pristine
    other = json.loads(json.dumps(report))
    other["submission"]["model"] = "another"
    other["release"]["configs"][CONFIG]["fingerprint"] = "0" * 64  # same release.json, other file content
    paths = []
    for name, r in (("a", report), ("b", other)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "report.json").write_text(json.dumps(r))
        paths.append(tmp_path / name)
    board = leaderboard(paths)
    assert list(board["main"]["rows"]) == [report["submission"]["model"]]
    assert [t["differs_in"] for t in board["not_comparable"]] == [["release files scored"]]


def _holder(folder: Path, name: str = LOCK_NAME) -> subprocess.Popen:
    """A separate process that takes `folder`'s lock and holds it until killed."""
    code = ("import sys, time; from pathlib import Path; from wsp_eval.folder_lock import exclusive\n"
            f"with exclusive(Path({str(folder)!r}), 'a test holder', {name!r}):\n"
            "    print('held', flush=True); time.sleep(600)")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_scoring_into_one_folder_refuses_and_a_killed_holders_lock_is_taken_over(pristine, tmp_path):
    release, sub, report = pristine
    out = tmp_path / "report"
    holder = _holder(out)
    try:
        with pytest.raises(ScoreError, match=f"pid {holder.pid}"):
            score_submission(sub, release, out, progress=False)
        assert not (out / "report.json").exists()
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    assert (out / LOCK_NAME).exists()  # the killed holder's file is left behind: its lock is not
    again = score_submission(sub, release, out, progress=False)
    assert again["platforms"] == report["platforms"]
    assert not (out / LOCK_NAME).exists() and not (sub / LOCK_NAME).exists()  # a finished run leaves no lock file


def test_two_concurrent_scorings_one_refuses(pristine, tmp_path):
    release, sub, _ = pristine
    out = tmp_path / "report"
    cmd = [sys.executable, "-m", "wsp_eval.cli", "score", str(sub), "--release", str(release), "--out", str(out),
           "--quiet"]
    first = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while not (out / LOCK_NAME).exists() or not (out / LOCK_NAME).read_text():
        assert time.time() < deadline and first.poll() is None, first.communicate()
        time.sleep(0.05)
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    first.communicate(timeout=600)
    assert first.returncode == 0
    assert second.returncode == 2 and f"pid {first.pid}" in second.stderr and "wsp score" in second.stderr


def test_generate_and_build_refuse_a_folder_in_use(pristine, tmp_path):
    import numpy as np

    from wsp_data.build import BuildError, build
    from wsp_data.builders import BuildConfig
    from wsp_eval.generate import GenerateError, generate

    release = pristine[0]
    sub = tmp_path / "sub"
    holder = _holder(sub)
    try:
        with pytest.raises(GenerateError, match=f"pid {holder.pid}"):
            generate(lambda first, actions, fps, seed: np.repeat(first[None], len(actions) + 1, 0), release, sub, seeds=(0,),
                     name="still", progress=False)
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
    out = tmp_path / "rel"
    holder = _holder(out / ".wsp-logs", "build_t1_maniskill.lock")
    try:
        with pytest.raises(BuildError, match=f"pid {holder.pid}"):  # refused before any simulator starts
            build(BuildConfig("t1", "maniskill", 1, ("PickCube",)), out, progress=False)
    finally:
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
