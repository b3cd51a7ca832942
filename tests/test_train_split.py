"""The training split: a second config in the same release, LeRobot's dataloader, no test seed leaks."""

from __future__ import annotations

import json
import shutil

import pytest

from wsp_data.schema import RELEASE_JSON, SEED_BASE, SEED_SPAN


@pytest.fixture(scope="module")
def release(t1_release, tmp_path_factory):
    from wsp_data.build import build
    from wsp_data.builders import BuildConfig

    out = tmp_path_factory.mktemp("train") / "worldsimprobe"
    shutil.copytree(t1_release, out)
    result = build(BuildConfig("train", "maniskill", 2, ("PickCube", "PushCube")), out, progress=False)
    assert result.assembled and result.report["kept"] == 2
    return out


def test_release_holds_both_configs(release):
    from datasets import load_dataset

    train = load_dataset(str(release), "train_maniskill", split="test")
    t1 = load_dataset(str(release), "t1_maniskill", split="test")
    assert [r["roles"] for r in train] == [["expert"], ["expert"]]
    assert set(train["task"]) == {"PickCube", "PushCube"} and all(s == [True] for s in train["success"])
    assert len(t1) >= 3
    card = (release / "README.md").read_text()
    assert "config_name: t1_maniskill" in card and "config_name: train_maniskill" in card
    rel = json.loads((release / RELEASE_JSON).read_text())
    assert set(rel["configs"]) == {"t1_maniskill", "train_maniskill"}
    for config, split in (("train_maniskill", "train"), ("t1_maniskill", "test")):  # LeRobot's info.json splits
        info = json.loads((release / config / "meta" / "info.json").read_text())
        assert list(info["splits"]) == [split], (config, info["splits"])


def test_no_test_seed_leaks_into_train(release):
    from datasets import load_dataset

    rel = json.loads((release / RELEASE_JSON).read_text())
    ranges = sorted(tuple(r) for r in rel["seed_ranges"].values())
    assert all(a[1] < b[0] for a, b in zip(ranges, ranges[1:]))  # documented ranges are disjoint
    train = set(load_dataset(str(release), "train_maniskill", split="test")["seed"])
    t1 = set(load_dataset(str(release), "t1_maniskill", split="test")["seed"])
    assert not train & t1
    assert all(SEED_BASE["train"] <= s < SEED_BASE["train"] + SEED_SPAN for s in train)
    assert all(SEED_BASE["t1"] <= s < SEED_BASE["t1"] + SEED_SPAN for s in t1)


def test_lerobot_dataloader_trains_on_it(release):
    """LeRobot's own dataset + torch DataLoader yield batches with action chunks (what a world model eats)."""
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("worldsimprobe/train_maniskill", root=release / "train_maniskill",
                        delta_timestamps={"action": [0.0, 0.05, 0.1, 0.15]})
    batch = next(iter(torch.utils.data.DataLoader(ds, batch_size=8, shuffle=True, num_workers=0)))
    assert batch["observation.images.base_camera"].shape == (8, 3, 128, 128)
    assert batch["action"].shape == (8, 4, 8)
    assert ds.meta.episodes[0]["wsp.suite"] == "train"
