"""`scripts/train_bc_policies.py` without training (seconds): each platform's recipe is the one its shipped
checkpoints were trained with, and the trainer's records rebuilt from the shipped training_config.json equal the
metadata stored in every shipped checkpoint, byte for byte. Retraining itself is the command in the script's
docstring (hours of CPU)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from wsp_data.platforms.bc_policy import STAGES, TRAINING_CONFIG

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "train_bc_policies.py"


@pytest.fixture(scope="module")
def trainer_module():
    spec = importlib.util.spec_from_file_location("train_bc_policies", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while the script runs
    spec.loader.exec_module(module)
    return module


def shipped(platform: str) -> tuple[Path, dict]:
    folder = ROOT / "wsp_data" / "platforms" / platform / "checkpoints"
    return folder, json.loads((folder / TRAINING_CONFIG).read_text())


def meta(path: Path) -> str:
    return torch.load(path, map_location="cpu", weights_only=True)["meta"]


def test_every_platform_has_a_recipe_and_a_trainer(trainer_module):
    assert set(trainer_module.RECIPES) == set(trainer_module.TRAINERS) == {"maniskill", "libero", "aloha"}


@pytest.mark.parametrize("platform", ["maniskill", "libero", "aloha"])
def test_recipe_is_the_shipped_checkpoints_recipe(trainer_module, platform):
    recipe = trainer_module.RECIPES[platform]
    _, config = shipped(platform)
    for task, tc in config["tasks"].items():
        assert tc["demos"] == recipe.demos and tc["noisy_rollouts_per_demo"] == recipe.noisy_rollouts, task
        assert tc.get("noise_std", tc.get("noise_std_rad")) == recipe.noise_std
        assert tc.get("noise_rho") == recipe.noise_rho
        assert tc["success"]["late"]["seeds"] == recipe.eval_seeds
        assert ("test_range_success" in tc) == (recipe.test_seeds is not None)
        assert trainer_module.fit_record(recipe.fit) == {k: tc[k] for k in trainer_module.FIT_FIELDS}


def _data(trainer_module, cls, tc: dict, stored: dict):
    """The `TaskData` a collection with the shipped record's outcome returns (zero features of its shapes)."""
    if cls.platform == "maniskill":
        n = tc["samples"]["total"]
        info = {"demo_seeds": tc["demo_seeds"], "skipped_seeds": tc["skipped_seeds"],
                "demonstration_samples": tc["samples"]["demonstration"], "noisy_samples": tc["samples"]["noisy"],
                "expert_max_length": tc["expert_max_length"], "collect_seconds": tc["collect_seconds"],
                "expert_mean_jerk": tc["expert_mean_jerk"]}
    else:
        n = tc["samples"]
        info = {k: tc[k] for k in ("demo_seeds", "skipped_seeds", "expert_max_length", "noisy_rollouts_per_demo",
                                   cls.noise_std_key, "noisy_samples", "collect_seconds")}
    out_dim = stored.get("out_dim", 8)
    return trainer_module.TaskData(np.zeros((n, stored["in_dim"]), np.float32), np.zeros((n, out_dim), np.float32),
                                   tc["expert_mean_length"], info)


@pytest.mark.parametrize("platform", ["maniskill", "libero", "aloha"])
def test_records_reproduce_the_shipped_checkpoint_metadata(trainer_module, platform):
    folder, config = shipped(platform)
    cls = trainer_module.TRAINERS[platform]
    trainer = object.__new__(cls)  # without __init__: ManiSkill's opens a simulator for the joint limits
    trainer.recipe, trainer.out, trainer.cache = trainer_module.RECIPES[platform], folder, None
    for task, tc0 in config["tasks"].items():
        stored = json.loads(meta(trainer.checkpoint_path(task, "late")))
        if platform == "maniskill":
            trainer.arm_limits = stored["arm_limits"]
        tc, base = trainer.record(task, _data(trainer_module, cls, tc0, stored), tc0["loss_every_500_steps"],
                                  tc0["train_seconds"])
        added = {"success", "test_range_success", "checkpoint_sha256", "checkpoint_bytes", "expert_mean_jerk",
                 "total_seconds"}
        if not cls.sort_record:  # ManiSkill's record is written in its own key order
            assert list(tc) == [k for k in tc0 if k not in added], task
        assert tc == {k: v for k, v in tc0.items() if k not in added}, task
        for stage in STAGES:
            success = {k: v for k, v in tc0["success"][stage].items() if k != "seconds"}
            full = dict(base, stage=stage, training_steps=tc["stage_steps"][stage], success=success)
            assert json.dumps(full, sort_keys=True) == meta(trainer.checkpoint_path(task, stage)), (task, stage)


def test_options_override_the_recipe_and_are_checked(trainer_module):
    args, recipe = trainer_module.parse(["--platform", "aloha", "--early-steps", "100", "--demos", "3"])
    base = trainer_module.RECIPES["aloha"]
    assert recipe.demos == 3 and recipe.fit.early_steps == 100 and recipe.fit.steps == base.fit.steps
    assert recipe.test_seeds == base.test_seeds and args.tasks is None
    for argv in (["--platform", "libero", "--noise-rho", "0.5"], ["--platform", "aloha", "--cache", "x"],
                 ["--platform", "maniskill", "--tasks", "StackCube"],
                 ["--platform", "maniskill", "--early-steps", "30000"]):
        with pytest.raises(SystemExit):
            trainer_module.parse(argv)
