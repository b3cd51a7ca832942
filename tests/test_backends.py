"""Backends are found by name; a heavy backend without its checkpoint, package or endpoint fails with a clear
message before any scoring (nothing downloads), through the API and through the CLI."""

from __future__ import annotations

import subprocess
import sys

import pytest

from wsp_eval.backends import FLOW, JUDGE, TRACKER, BackendSpec, make
from wsp_eval.backends.errors import BackendUnavailable


def test_defaults_are_registered_and_offline():
    assert {"dis", "dpflow"} <= set(FLOW) and {"lk", "tapnext"} <= set(TRACKER) and {"net", "rules", "openai"} <= set(JUDGE)
    b = make(BackendSpec(), ("flow", "tracker"))
    assert (b.flow.name, b.tracker.name, b.judge) == ("dis", "lk", None)
    assert set(b.describe()) == {"flow", "tracker"} and "opencv" in b.describe()["flow"]["version"]


@pytest.mark.parametrize("spec, message", [
    (BackendSpec(flow="dpflow"), "needs a local checkpoint: --flow-checkpoint"),
    (BackendSpec(flow="dpflow", flow_checkpoint="/nonexistent/dpflow.ckpt"), "/nonexistent/dpflow.ckpt not found"),
    (BackendSpec(tracker="tapnext"), "needs a local checkpoint: --tracker-checkpoint"),
    (BackendSpec(tracker="tapnext", tracker_checkpoint="/nonexistent/t.npz"), "/nonexistent/t.npz not found"),
    (BackendSpec(judge="openai"), "needs --judge-url"),
    (BackendSpec(judge="net", judge_checkpoint="/nonexistent/judge.onnx"), "weights not found at /nonexistent/judge.onnx"),
])
def test_missing_weights_or_endpoint_fail_clearly(spec, message):
    with pytest.raises(BackendUnavailable, match=message):
        make(spec)


def test_checkpoint_present_but_package_missing(tmp_path):
    ckpt = tmp_path / "w.ckpt"
    ckpt.write_bytes(b"weights")
    for spec, package in ((BackendSpec(flow="dpflow", flow_checkpoint=str(ckpt)), "ptlflow"),
                          (BackendSpec(tracker="tapnext", tracker_checkpoint=str(ckpt)), "tapnet")):
        try:
            __import__(package)
        except ImportError:
            with pytest.raises(BackendUnavailable, match=f"needs {'the ' if package == 'tapnet' else ''}{package}"):
                make(spec)


def test_unknown_backend_name():
    with pytest.raises(BackendUnavailable, match="unknown flow backend 'raft'; known: dis, dpflow"):
        BackendSpec(flow="raft")


def test_cli_reports_a_missing_checkpoint_or_endpoint_without_a_traceback(suites_release, tmp_path):
    from wsp_eval.baselines import write_baseline

    sub = tmp_path / "sub"
    write_baseline("static", suites_release, sub, seeds=(0,))
    base = [sys.executable, "-m", "wsp_eval.cli", "score", str(sub), "--release", str(suites_release), "--quiet"]
    for extra, message in ((["--flow", "dpflow", "--flow-checkpoint", "/nonexistent/dpflow.ckpt"], "not found"),
                           (["--judge", "openai", "--judge-url", "http://127.0.0.1:9/v1", "--judge-model", "m"],
                            "127.0.0.1:9")):
        r = subprocess.run(base + ["--out", str(tmp_path / extra[0][2:])] + extra, capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 2 and "Traceback" not in r.stderr and message in r.stderr, r.stderr
