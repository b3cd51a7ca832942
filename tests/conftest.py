"""Shared fixtures: one tiny real T1 build (ManiSkill, rendered, LeRobot-written) reused by the tests.

Hugging Face caches go to a temp folder and every hub access is offline (DESIGN: nothing downloads).
"""

from __future__ import annotations

import os
import tempfile

_HF = tempfile.mkdtemp(prefix="wsp-hf-")
os.environ.update(HF_HOME=_HF, HF_HUB_OFFLINE="1", HF_DATASETS_OFFLINE="1", TQDM_DISABLE="1")

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

TINY = dict(suite="t1", platform="maniskill", count=4, tasks=("PickCube", "PushCube"), seed=0, max_attempts=8)
TINY_ARGS = {k: v for k, v in TINY.items() if k != "platform"}


def build_tiny(tmp_path_factory, suite: str, count: int, tasks: tuple[str, ...], **config) -> Path:
    """Build one config of a tiny real release into a fresh folder named `worldsimprobe`."""
    from wsp_data.build import build
    from wsp_data.builders import BuildConfig

    out = tmp_path_factory.mktemp(suite) / "worldsimprobe"
    result = build(BuildConfig(suite, "maniskill", count, tuple(tasks), **config), out, progress=False)
    assert result.assembled
    return out


def instance_rows(release: Path, config: str):
    """The instance table, as users load it with `datasets`."""
    from datasets import load_dataset

    return load_dataset(str(release), config, split="test")


def open_lerobot(release: Path, config: str):
    """The config as a LeRobotDataset, opened offline from the release folder."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(f"worldsimprobe/{config}", root=release / config)


@pytest.fixture(scope="session")
def t1_release(tmp_path_factory) -> Path:
    """A real 4-instance T1 release folder named `worldsimprobe`."""
    out = build_tiny(tmp_path_factory, **TINY_ARGS)
    assert json.loads((out / "t1_maniskill" / "build_report.json").read_text())["kept"] >= 3
    return out
