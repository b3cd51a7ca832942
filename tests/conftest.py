"""Shared fixtures: one tiny real T1 build (ManiSkill, rendered, LeRobot-written) reused by the tests.

Hugging Face caches go to a temp folder and every hub access is offline (DESIGN: nothing downloads).
"""

from __future__ import annotations

import os
import tempfile

_HF = tempfile.mkdtemp(prefix="wsp-hf-")
os.environ.update(HF_HOME=_HF, HF_HUB_OFFLINE="1", HF_DATASETS_OFFLINE="1", TQDM_DISABLE="1")

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

TINY = dict(suite="t1", platform="maniskill", count=4, tasks=("PickCube", "PushCube"), seed=0, max_attempts=8)


@pytest.fixture(scope="session")
def tiny_config():
    from wsp_data.builders import BuildConfig

    return BuildConfig(**TINY)


@pytest.fixture(scope="session")
def t1_release(tmp_path_factory, tiny_config) -> Path:
    """A real 4-instance T1 release folder named `worldsimprobe`."""
    from wsp_data.build import build

    out = tmp_path_factory.mktemp("straight") / "worldsimprobe"
    result = build(tiny_config, out, progress=False)
    assert result.assembled and result.report["kept"] >= 3
    return out
