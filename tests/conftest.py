"""Shared fixtures: the tiny real releases (ManiSkill and LIBERO, rendered, LeRobot-written) that the tests
share, each built once per run for every module and every xdist worker (`tiny_releases.py`).

Hugging Face caches go to a temp folder and every hub access is offline (spec §4.6: nothing downloads).
"""

from __future__ import annotations

from tiny_releases import offline_environment

offline_environment()

import json  # noqa: E402
import os  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

from tiny_releases import (  # noqa: E402,F401
    ALOHA_SUITES, ALOHA_TASKS, LIBERO_SUITES, LIBERO_TASKS, T2_TASKS, TINY, build_config, shared_release,
)
from wsp_eval.release_format import DEFAULT_RELEASE_NAME, RELEASE_JSON  # noqa: E402


def build_tiny(tmp_path_factory, suite: str, count: int, tasks: tuple[str, ...], out: Path | None = None,
               platform: str = "maniskill", **config) -> Path:
    """Build one config of a tiny real release into `out` (default: a fresh folder named `worldsimprobe`), for
    tests that need a build of their own."""
    out = out or tmp_path_factory.mktemp(suite) / DEFAULT_RELEASE_NAME
    return build_config(out, suite, platform, count, tasks, **config)


def tiny_build_command(out: Path, *extra: str) -> list[str]:
    """`wsp build` of the shared `t1` release's config into `out`, as a command line (tests of building itself)."""
    return [sys.executable, "-m", "wsp_eval.cli", "build", "--suite", TINY["suite"], "--platform", TINY["platform"],
            "--count", str(TINY["count"]), "--tasks", *TINY["tasks"], "--out", str(out), "--quiet", *extra]


def release_files(release: Path) -> dict:
    """path → sha256 of every file a release lists in its release.json."""
    return json.loads((release / RELEASE_JSON).read_text())["files"]


SHARED = ("t1_release", "suites_release", "aloha_release", "libero_release")  # the pre-build's finishing order


def pytest_collection_modifyitems(items) -> None:
    """Test files that need no shared release run first, then those needing t1, suites, LIBERO, so xdist
    workers seldom wait for a release still being built. Files stay whole and keep their own order."""
    def need(item) -> int:
        return max((SHARED.index(f) + 1 for f in item.fixturenames if f in SHARED), default=0)

    per_file: dict = {}
    for item in items:
        per_file[item.path] = max(per_file.get(item.path, 0), need(item))
    items.sort(key=lambda item: per_file[item.path])


@pytest.fixture(scope="session")
def shared_root(tmp_path_factory) -> Path:
    """Where the shared tiny releases live: the pre-built folder `scripts/test.sh` names, else this run's temp
    folder common to all xdist workers."""
    if os.environ.get("WSP_TEST_RELEASES"):
        return Path(os.environ["WSP_TEST_RELEASES"])
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "shared-releases"


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
def t1_release(shared_root) -> Path:
    """A real 4-instance T1 release folder named `worldsimprobe`."""
    out = shared_release("t1", shared_root)
    assert json.loads((out / "t1_maniskill" / "build_report.json").read_text())["kept"] >= 3
    return out


@pytest.fixture(scope="session")
def suites_release(shared_root) -> Path:
    """One real release holding tiny T2 (3 replays over T2_TASKS), T3 (8, PickCube: one group of all eight
    sources), T4 (6, PickCube: two of each kind) and T5 (8, PickCube: one per primitive) configs."""
    return shared_release("suites", shared_root)


@pytest.fixture(scope="session")
def libero_release(shared_root) -> Path:
    """One real LIBERO release over LIBERO_TASKS (a tall can, a flat box: push and tap need the low one):
    T1 (2 triplets), T2 (2 cross-task replays), T3 (one group of all eight sources, on the first task), T4 (one
    per kind), T5 (one per primitive), train (2)."""
    return shared_release("libero", shared_root)


@pytest.fixture(scope="session")
def aloha_release(shared_root) -> Path:
    """One real ALOHA release over ALOHA_TASKS (a two-arm hand-over, a one-arm lift): T1 (2 triplets), T2 (2
    cross-task replays), T4 (one per kind, on the hand-over), T5 (one per primitive, over ALOHA_T5_TASKS), train
    (2)."""
    return shared_release("aloha", shared_root)
