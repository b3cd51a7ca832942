"""The scoring-only install (`pip install .`, no extras) in a fresh virtual environment: no torch, simulator,
LeRobot or `datasets` in it; `wsp info`, `wsp validate` and `wsp score` work on a tiny release built by the full
install and give exactly the full install's scores; build-side commands stop with one line naming the extra.

Size: measured 649 MB on Python 3.12 (docs in the README's "Scoring-only install"); the test fails above 700 MB so
that a new heavy dependency in the base install is noticed (the issue's 400 MB is out of reach: numpy, OpenCV and
pyarrow alone take 393 MB). pip reads the package index configured on the machine (set-up time, as `make setup`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from wsp_eval.cli import main
from wsp_eval.baselines import write_baseline

ROOT = Path(__file__).resolve().parents[1]
MAX_BYTES = 700e6


def _size(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file() and not f.is_symlink())


@pytest.fixture(scope="module")
def lite(tmp_path_factory) -> Path:
    venv = tmp_path_factory.mktemp("lite") / "venv"
    subprocess.run([getattr(sys, "_base_executable", sys.executable), "-m", "venv", str(venv)], check=True,
                   timeout=300)
    out = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "-q", str(ROOT)],
                         capture_output=True, text=True, timeout=1200)
    assert out.returncode == 0, out.stderr[-3000:]
    return venv


def _wsp(venv: Path, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run([str(venv / "bin" / "wsp"), *args], capture_output=True, text=True, timeout=900, cwd=cwd,
                          env=env)


def test_scoring_install_is_light(lite):
    code = ("import importlib.util as u; print([m for m in ('torch', 'sapien', 'mani_skill', 'mujoco', 'robosuite', "
            "'lerobot', 'datasets', 'selenium') if u.find_spec(m)])")
    out = subprocess.run([str(lite / "bin" / "python"), "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
    assert _size(lite) < MAX_BYTES


def test_scoring_install_scores_as_the_full_install(lite, suites_release, tmp_path):
    sub = tmp_path / "sub"
    write_baseline("action_blind", suites_release, sub, seeds=(0,))
    assert main(["score", str(sub), "--release", str(suites_release), "--out", str(tmp_path / "full"), "--quiet"]) == 0
    info = _wsp(lite, "info", str(suites_release), cwd=tmp_path)
    assert info.returncode == 0 and "t5_maniskill" in info.stdout, info.stderr
    valid = _wsp(lite, "validate", str(sub), "--release", str(suites_release), cwd=tmp_path)
    assert valid.returncode == 0 and "valid" in valid.stdout, valid.stderr
    scored = _wsp(lite, "score", str(sub), "--release", str(suites_release), "--out", str(tmp_path / "lite"),
                  "--quiet", cwd=tmp_path)
    assert scored.returncode == 0, scored.stderr[-3000:]
    full, light = (json.loads((tmp_path / k / "report.json").read_text()) for k in ("full", "lite"))
    per = lambda r: {(i["config"], i["instance_id"]): i["score"] for i in r["instances"]}  # noqa: E731
    assert per(light) == per(full) and len(per(full)) == 25
    build = _wsp(lite, "build", "--platform", "maniskill", "--suite", "t1", "--count", "1", "--out", "x", cwd=tmp_path)
    assert build.returncode == 2 and "worldsimprobe[build]" in build.stderr
    assert len(build.stderr.strip().splitlines()) == 1 and "Traceback" not in build.stderr
    gen = _wsp(lite, "generate", "--model", "reference", "--release", str(suites_release), "--out", "g", cwd=tmp_path)
    assert gen.returncode == 2 and "worldsimprobe[train]" in gen.stderr and "Traceback" not in gen.stderr
