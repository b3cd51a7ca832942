"""Rebuild ALOHA's T3 policy checkpoints from scratch: behaviour cloning of the scripted experts, CPU only.

    .venv/bin/python scripts/train_aloha_policies.py [--tasks …] [--demos 50] [--noisy-rollouts 2]
        [--noise-std 0.04] [--steps 20000] [--early-steps 200] [--eval-seeds 20] [--test-seeds 20] [--out DIR]

Per task: script `--demos` verified expert episodes on training seeds 0, 1, … (`AlohaExpertSource`; failed
seeds are skipped and recorded), replay each to record its states, re-run the closed-loop script
`--noisy-rollouts` times per seed with Gaussian noise (σ `--noise-std` rad) added to the executed arm joint
targets while each visited state is labelled with the script's own clean action (DART-style recovery data),
train the MLP of `wsp_data.platforms.aloha.t3` on (state features → arm targets relative to the arm joints and
both gripper commands) with `maniskill.policies.fit` (AdamW, cosine decay, batch 256, one thread, seed 0), keep
the weights after `--early-steps` (early) and `--steps` (late), measure closed-loop success of both on
`--eval-seeds` held-out training seeds (910,000 + k; stored in the checkpoint and its provenance) and on
`--test-seeds` test-range scene seeds (3,000,000 + 800k: the first candidate seed of T3's group k; recorded in
`training_config.json` only, never used to choose anything), and write `<task>_<stage>.pt` and
`training_config.json` into `--out`. The same arguments give the same weights (bit for bit).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from wsp_data.platforms.aloha.experts import SCRIPTS, AlohaExpertSource, OutOfTime, Script  # noqa: E402
from wsp_data.platforms.aloha.t3 import (  # noqa: E402
    ARM_ACTION, CHECKPOINT_DIR, MAX_DELTA, T3_TASKS, AlohaPolicySource, action_target, checkpoint_path,
    feature_names, features,
)
from wsp_data.platforms.bc_model import fit, save_checkpoint, start_training  # noqa: E402
from wsp_data.platforms.bc_policy import (  # noqa: E402
    MAX_STEPS_FACTOR, SETTLE_STEPS, STAGES, closed_loop_success, sha256, training_log)
from wsp_data.schema import scene_seed  # noqa: E402

EVAL_SEED_BASE = 910_000
GROUP_SIZE = 8  # T3's group k proposes scene_seed("t3", 8k, 0) first (`builders.t3`)


class NoisyScript(Script):
    """The expert's script executing noisy arm targets, recording (state, step, clean action)."""

    def __init__(self, p, seed: int, std: float, k: int):
        super().__init__(p, seed)
        self.rng, self.std = np.random.default_rng([seed, 11, k]), std
        self.samples: list[tuple[object, int, np.ndarray]] = []

    def act(self) -> None:
        if len(self.actions) >= self.max_steps:
            raise OutOfTime
        clean = self.command(self.hand)
        self.samples.append((self.observation, len(self.actions), clean))
        noisy = clean.copy()
        noisy[list(ARM_ACTION)] += self.rng.normal(0.0, self.std, 12).astype(np.float32)
        noisy[list(ARM_ACTION)] = np.clip(noisy[list(ARM_ACTION)], *self.p.qlimits[:12].T)
        self.actions.append(noisy)
        self.observation = self.p.step(noisy)


def collect(task: str, demos: int, noisy: int, std: float, log) -> tuple[np.ndarray, np.ndarray, float, dict]:
    t0 = time.perf_counter()
    src = AlohaExpertSource(task)
    episodes, seeds, skipped, seed = [], [], [], 0
    extra: list[tuple[object, int, np.ndarray]] = []
    try:
        while len(episodes) < demos:
            actions = src.trajectory(seed)
            if actions is None:
                skipped.append(seed)
            else:
                ro = src.replayer.replay(seed, actions)
                episodes.append((ro.observations[:-1], actions))
                seeds.append(seed)
                for k in range(noisy):
                    script = NoisyScript(src.replayer, seed, std, k)
                    try:  # success or not: every visited state is labelled with the clean action
                        SCRIPTS[task](script)
                    except OutOfTime:
                        pass
                    extra += script.samples
            seed += 1
    finally:
        src.close()
    ref = float(np.mean([len(a) for _, a in episodes]))
    n = len(src.spec.objects)
    X = np.stack([features(ob, n, t, ref) for obs, _ in episodes for t, ob in enumerate(obs)]
                 + [features(ob, n, t, ref) for ob, t, _ in extra])
    Y = np.stack([action_target(ob, a) for obs, acts in episodes for ob, a in zip(obs, acts)]
                 + [action_target(ob, a) for ob, _, a in extra]).astype(np.float32)
    log(f"{task}: {len(episodes)} demonstrations ({len(skipped)} seeds skipped) + {len(extra)} noisy samples, "
        f"{len(X)} samples")
    info = {"demo_seeds": seeds, "skipped_seeds": skipped, "expert_max_length": int(max(len(a) for _, a in episodes)),
            "noisy_rollouts_per_demo": noisy, "noise_std_rad": std, "noisy_samples": len(extra),
            "collect_seconds": round(time.perf_counter() - t0, 1)}
    return X, Y, ref, info


def evaluate(task: str, stage: str, out: Path, seeds: list[int]) -> dict:
    return closed_loop_success(AlohaPolicySource(task, stage, checkpoint_dir=out), seeds)[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", nargs="+", default=list(T3_TASKS), choices=T3_TASKS)
    ap.add_argument("--demos", type=int, default=50)
    ap.add_argument("--noisy-rollouts", type=int, default=2)
    ap.add_argument("--noise-std", type=float, default=0.04, help="rad added to the executed arm joint targets")
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--early-steps", type=int, default=200)
    ap.add_argument("--eval-seeds", type=int, default=20)
    ap.add_argument("--test-seeds", type=int, default=20)
    ap.add_argument("--out", type=Path, default=CHECKPOINT_DIR)
    args = ap.parse_args(argv)
    if not 0 < args.early_steps < args.steps:
        ap.error("need 0 < --early-steps < --steps")
    log, out = training_log, args.out
    config, config_path = start_training(out)
    eval_seeds = [EVAL_SEED_BASE + k for k in range(args.eval_seeds)]
    test_seeds = [scene_seed("t3", GROUP_SIZE * k, 0) for k in range(args.test_seeds)]
    for task in args.tasks:
        X, Y, ref, info = collect(task, args.demos, args.noisy_rollouts, args.noise_std, log)
        cfg = dict(seed=0, steps=args.steps, early_steps=args.early_steps, batch=256, lr=1e-3, weight_decay=1e-4,
                   hidden=[256, 256], std_floor=1e-3)
        t0 = time.perf_counter()
        early, late, losses = fit(X, Y, cfg, log)
        tc = {"demos": args.demos, **info, "samples": int(len(X)), "expert_mean_length": ref,
              "features": feature_names(task),
              "target": "the expert's 12 arm joint targets relative to the arm joints (rad), then both gripper "
                        "commands",
              "architecture": f"MLP {X.shape[1]}-256-256-{Y.shape[1]}, ReLU, standardised inputs and targets",
              **{k: cfg[k] for k in ("seed", "steps", "early_steps", "batch", "lr", "weight_decay", "hidden")},
              "stage_steps": {"early": cfg["early_steps"], "late": cfg["steps"]},
              "inference": f"deterministic; arm targets = joints + output bounded to +-{MAX_DELTA} rad, clipped to "
                           f"the joint limits; grippers 1 (open) if the output >= 0.5 else 0; stops once success "
                           f"held {SETTLE_STEPS} steps or at ceil({MAX_STEPS_FACTOR} x expert mean length)"}
        stable = {k: v for k, v in tc.items() if k != "collect_seconds"}
        meta = dict(task=task, in_dim=int(X.shape[1]), out_dim=int(Y.shape[1]), hidden=cfg["hidden"],
                    feature_names=feature_names(task), expert_mean_length=ref, total_training_steps=cfg["steps"],
                    training_config=stable)
        models = dict(zip(STAGES, (early, late)))
        tc["train_seconds"], tc["loss_every_500_steps"] = round(time.perf_counter() - t0, 1), losses
        for stage, model in models.items():
            save_checkpoint(checkpoint_path(task, stage, out), model,
                            dict(meta, stage=stage, training_steps=tc["stage_steps"][stage]))
        tc["success"], tc["test_range_success"], tc["checkpoint_sha256"] = {}, {}, {}
        for stage, model in models.items():
            res = evaluate(task, stage, out, eval_seeds)
            log(f"{task} {stage}: success {res['successes']}/{res['seeds']}, mean {res['mean_steps']:.0f} steps")
            tc["success"][stage] = res
            path = checkpoint_path(task, stage, out)
            save_checkpoint(path, model, dict(meta, stage=stage, training_steps=tc["stage_steps"][stage], success=res))
            tc["checkpoint_sha256"][stage] = sha256(path)
            if test_seeds:
                res = evaluate(task, stage, out, test_seeds)
                log(f"{task} {stage}: test-range success {res['successes']}/{res['seeds']}")
                tc["test_range_success"][stage] = res
        config["tasks"][task] = tc
        config_path.write_text(json.dumps(config, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
