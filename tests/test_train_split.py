"""The training split: a second config in the same release, LeRobot's dataloader, no test seed leaks, and
LeRobot's own checker (lerobot-doctor) and trainer (lerobot-train, ACT and Diffusion Policy) on it as they are."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

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


# -- LeRobot's own tools on the train splits, as a LeRobot user runs them ---------------------------------------
BIN = Path(sys.executable).parent
POLICIES = {  # unchanged lerobot-train flags; no pretrained backbone (nothing downloads), CPU, two steps
    "act": ["--policy.type=act", "--policy.pretrained_backbone_weights=null"],
    "diffusion": ["--policy.type=diffusion", "--policy.pretrained_backbone_weights=null"],
}
POLICY_INPUTS = {"maniskill": {"observation.images.base_camera", "observation.state", "observation.ee_pose"},
                 "libero": {"observation.images.agentview", "observation.state", "observation.ee_pose"},
                 "aloha": {"observation.images.head", "observation.state", "observation.ee_pose"}}


def _train_split(request, platform: str) -> Path:
    if platform == "maniskill":
        return request.getfixturevalue("release") / "train_maniskill"
    return request.getfixturevalue(f"{platform}_release") / f"train_{platform}"


@pytest.mark.parametrize("platform", ["maniskill", "libero", "aloha"])
def test_lerobot_doctor_finds_no_failure(request, platform):
    """lerobot-doctor fails a split with NaN values (it once found thousands in the padded object slots); the
    zero-variance warnings it still prints are for unused `sim.*` slots, which are not policy inputs."""
    split = _train_split(request, platform)
    r = subprocess.run([str(BIN / "lerobot-doctor"), "check", str(split)], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0 and "[FAIL]" not in r.stdout, r.stdout[-3000:] + r.stderr[-2000:]
    features = json.loads((split / "meta" / "info.json").read_text())["features"]
    policy_inputs = {k for k, f in features.items() if k.startswith("observation.") or f["dtype"] in ("image", "video")}
    assert policy_inputs == POLICY_INPUTS[platform]  # no robot mask, no padded simulator state


@pytest.mark.parametrize("policy", sorted(POLICIES))
@pytest.mark.parametrize("platform", ["maniskill", "libero", "aloha"])
def test_lerobot_train_runs_on_the_train_split(request, tmp_path, platform, policy):
    """The checkpoint it saves is the full policy (Diffusion Policy: 1 GB of weights + 2 GB of optimizer state);
    it is checked, then deleted, because pytest keeps its last three runs' temporary folders: kept, the six
    checkpoints filled a CI machine's disk (9.7 GB per run)."""
    split = _train_split(request, platform)
    out = tmp_path / "run"
    try:
        r = subprocess.run(
            [str(BIN / "lerobot-train"), f"--dataset.repo_id=worldsimprobe/{split.name}", f"--dataset.root={split}",
             *POLICIES[policy], "--policy.device=cpu", "--policy.push_to_hub=false", "--wandb.enable=false",
             "--steps=2", "--batch_size=2", "--num_workers=0", "--log_freq=1", "--save_freq=2",
             f"--output_dir={out}"],
            capture_output=True, text=True, timeout=900, env={**os.environ, "HF_HUB_OFFLINE": "1"})
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
        logged = r.stdout + r.stderr
        assert "step:2" in logged and "loss:nan" not in logged.lower()
        checkpoint = next(out.glob("checkpoints/*"))
        config = json.loads((checkpoint / "pretrained_model" / "config.json").read_text())
        assert set(config["input_features"]) == POLICY_INPUTS[platform]  # the robot mask is never a camera
        assert (checkpoint / "pretrained_model" / "model.safetensors").stat().st_size > 1e6
    finally:
        shutil.rmtree(out, ignore_errors=True)
