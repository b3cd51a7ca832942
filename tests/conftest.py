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


def build_tiny(tmp_path_factory, suite: str, count: int, tasks: tuple[str, ...], out: Path | None = None,
               platform: str = "maniskill", **config) -> Path:
    """Build one config of a tiny real release into `out` (default: a fresh folder named `worldsimprobe`)."""
    from wsp_data.build import build
    from wsp_data.builders import BuildConfig

    out = out or tmp_path_factory.mktemp(suite) / "worldsimprobe"
    result = build(BuildConfig(suite, platform, count, tuple(tasks), **config), out, progress=False)
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


def assert_source_episodes(ds, rows) -> None:
    """Every instance has one unscored source episode (the unperturbed expert rollout, same task and scene
    seed, successful) besides its scored ones, and nothing else."""
    assert ds.num_episodes == sum(len(r["episode_indices"]) + 1 for r in rows)
    for r in rows:
        ep = ds.meta.episodes[r["source_episode_index"]]
        assert r["source_episode_index"] not in r["episode_indices"]
        assert r["source_episode_id"] == ep["wsp.episode_id"] == f"episode_{r['source_episode_index']:06d}"
        assert ep["wsp.role"] == "source" and ep["wsp.instance_id"] == r["instance_id"]
        assert ep["wsp.task"] == r["task"] and ep["wsp.seed"] == r["seed"] and ep["wsp.success"]
        assert ep["wsp.intervention"] == "{}"


@pytest.fixture(scope="session")
def t1_release(tmp_path_factory) -> Path:
    """A real 4-instance T1 release folder named `worldsimprobe`."""
    out = build_tiny(tmp_path_factory, **TINY_ARGS)
    assert json.loads((out / "t1_maniskill" / "build_report.json").read_text())["kept"] >= 3
    return out


T2_TASKS = ("PickCube", "PushCube", "PullCube")


@pytest.fixture(scope="session")
def suites_release(tmp_path_factory) -> Path:
    """One real release holding tiny T2 (3 replays over T2_TASKS), T3 (8, PickCube: one group of all eight
    sources), T4 (6, PickCube: two of each kind) and T5 (8, PickCube: one per primitive) configs."""
    out = tmp_path_factory.mktemp("suites") / "worldsimprobe"
    for suite, count, tasks in (("t2", 3, T2_TASKS), ("t3", 8, ("PickCube",)), ("t4", 6, ("PickCube",)),
                                ("t5", 8, ("PickCube",))):
        build_tiny(tmp_path_factory, suite, count, tasks, out=out)
    return out


LIBERO_TASKS = ("libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket",
                "libero_object/pick_up_the_butter_and_place_it_in_the_basket")
LIBERO_SUITES = (("t1", 2), ("t2", 2), ("t3", 8), ("t4", 3), ("t5", 4), ("train", 2))


@pytest.fixture(scope="session")
def libero_release(tmp_path_factory) -> Path:
    """One real LIBERO release over LIBERO_TASKS (a tall can, a flat box: push and tap need the low one):
    T1 (2 triplets), T2 (2 cross-task replays), T3 (one group of all eight sources, on the first task), T4 (one
    per kind), T5 (one per primitive), train (2)."""
    out = tmp_path_factory.mktemp("libero") / "worldsimprobe"
    for suite, count in LIBERO_SUITES:
        build_tiny(tmp_path_factory, suite, count, LIBERO_TASKS, out=out, platform="libero")
    return out
