"""Rebuild LIBERO's T3 policy checkpoints from scratch: behaviour cloning of the scripted experts, CPU only.

    .venv/bin/python scripts/train_libero_policies.py [--tasks …] [--demos 30] [--steps 20000]
                                                      [--early-steps 2000] [--eval-seeds 10] [--out DIR]

Per task: script `--demos` verified expert episodes on training seeds 0, 1, … (`LiberoExpertSource`; failed
seeds are skipped and recorded), replay each to record its states, re-run the closed-loop script
`--noisy-rollouts` times per seed with Gaussian noise (σ `--noise-std` = 0.1 OSC units) added to the executed arm
actions while each visited state is labelled with the script's own clean action (DART-style recovery data:
plain cloning of 30 demonstrations solved 0/10 held-out scenes on the can task), train the MLP of
`wsp_data.platforms.libero.t3` on (state features → the expert's OSC action) with `policies.fit` (the ManiSkill
recipe: AdamW, cosine decay, batch 256, one thread, seed 0), keep the weights after `--early-steps` (early) and
`--steps` (late), measure closed-loop success of both on `--eval-seeds` held-out training seeds (910,000 + k),
and write `<task>_<stage>.pt` (task's "/" as "__") and `training_config.json` into `--out`. The same arguments
give the same weights.
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

from wsp_data.platforms.libero.experts import LiberoExpertSource, PickPlaceScript  # noqa: E402
from wsp_data.platforms.libero.t3 import (  # noqa: E402
    CHECKPOINT_DIR, T3_TASKS, LiberoPolicySource, checkpoint_path, feature_names, features,
)
from wsp_data.platforms.bc_model import fit, save_checkpoint, start_training  # noqa: E402
from wsp_data.platforms.bc_policy import (  # noqa: E402
    MAX_STEPS_FACTOR, SETTLE_STEPS, STAGES, closed_loop_success, sha256, training_log)

EVAL_SEED_BASE = 910_000


class NoisyScript(PickPlaceScript):
    """The expert's script executing noisy arm actions, recording (state, clean action) pairs."""

    def __init__(self, p, spec, seed: int, std: float, k: int):
        super().__init__(p, spec, seed)
        self.rng, self.std = np.random.default_rng([seed, 11, k]), std
        self.samples: list[tuple[object, int, np.ndarray]] = []

    def act(self, a: np.ndarray) -> None:
        clean = np.asarray(a, dtype=np.float64).copy()
        clean[:6] = np.clip(clean[:6], -0.9, 0.9)
        self.samples.append((self.observation, len(self.actions), clean.astype(np.float32)))
        noisy = clean.copy()
        noisy[:6] += self.rng.normal(0.0, self.std, 6)
        super().act(noisy)


def collect(task: str, demos: int, noisy: int, std: float, log) -> tuple[np.ndarray, np.ndarray, float, dict]:
    t0 = time.perf_counter()
    src = LiberoExpertSource(task)
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
                    script = NoisyScript(src.replayer, src.spec, seed, std, k)
                    script.run()  # success or not: every visited state is labelled with the clean action
                    extra += script.samples
            seed += 1
    finally:
        src.close()
    ref = float(np.mean([len(a) for _, a in episodes]))
    n = len(src.spec.objects)
    X = np.stack([features(ob, n, t, ref) for obs, _ in episodes for t, ob in enumerate(obs)]
                 + [features(ob, n, t, ref) for ob, t, _ in extra])
    Y = np.concatenate([a for _, a in episodes] + [np.stack([a for _, _, a in extra])]).astype(np.float32)
    log(f"{task}: {len(episodes)} demonstrations ({len(skipped)} seeds skipped) + {len(extra)} noisy samples, "
        f"{len(X)} samples")
    info = {"demo_seeds": seeds, "skipped_seeds": skipped, "expert_max_length": int(max(len(a) for _, a in episodes)),
            "noisy_rollouts_per_demo": noisy, "noise_std": std, "noisy_samples": len(extra),
            "collect_seconds": round(time.perf_counter() - t0, 1)}
    return X, Y, ref, info


def evaluate(task: str, stage: str, out: Path, seeds: list[int]) -> dict:
    return closed_loop_success(LiberoPolicySource(task, stage, checkpoint_dir=out), seeds)[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tasks", nargs="+", default=list(T3_TASKS), choices=T3_TASKS)
    ap.add_argument("--demos", type=int, default=30)
    ap.add_argument("--noisy-rollouts", type=int, default=2)
    ap.add_argument("--noise-std", type=float, default=0.1, help="OSC units added to the executed arm actions")
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--early-steps", type=int, default=2000)
    ap.add_argument("--eval-seeds", type=int, default=10)
    ap.add_argument("--out", type=Path, default=CHECKPOINT_DIR)
    args = ap.parse_args(argv)
    if not 0 < args.early_steps < args.steps:
        ap.error("need 0 < --early-steps < --steps")
    log, out = training_log, args.out
    config, config_path = start_training(out)
    eval_seeds = [EVAL_SEED_BASE + k for k in range(args.eval_seeds)]
    for task in args.tasks:
        X, Y, ref, info = collect(task, args.demos, args.noisy_rollouts, args.noise_std, log)
        cfg = dict(seed=0, steps=args.steps, early_steps=args.early_steps, batch=256, lr=1e-3, weight_decay=1e-4,
                   hidden=[256, 256], std_floor=1e-3)
        t0 = time.perf_counter()
        early, late, losses = fit(X, Y, cfg, log)
        tc = {"demos": args.demos, **info, "samples": int(len(X)), "expert_mean_length": ref,
              "features": feature_names(task), "target": "the expert's OSC action (6 arm dims + gripper)",
              "architecture": f"MLP {X.shape[1]}-256-256-{Y.shape[1]}, ReLU, standardised inputs and targets",
              **{k: cfg[k] for k in ("seed", "steps", "early_steps", "batch", "lr", "weight_decay", "hidden")},
              "stage_steps": {"early": cfg["early_steps"], "late": cfg["steps"]},
              "inference": f"deterministic; arm clipped to +-0.9, gripper +1 if its output >= 0 else -1; stops once "
                           f"success held {SETTLE_STEPS} steps or at ceil({MAX_STEPS_FACTOR} x expert mean length)"}
        stable = {k: v for k, v in tc.items() if k != "collect_seconds"}
        meta = dict(task=task, in_dim=int(X.shape[1]), out_dim=int(Y.shape[1]), hidden=cfg["hidden"],
                    feature_names=feature_names(task), expert_mean_length=ref, total_training_steps=cfg["steps"],
                    training_config=stable)
        models = dict(zip(STAGES, (early, late)))
        tc["train_seconds"], tc["loss_every_500_steps"] = round(time.perf_counter() - t0, 1), losses
        for stage, model in models.items():
            save_checkpoint(checkpoint_path(task, stage, out), model,
                            dict(meta, stage=stage, training_steps=tc["stage_steps"][stage]))
        tc["success"], tc["checkpoint_sha256"] = {}, {}
        for stage, model in models.items():
            res = evaluate(task, stage, out, eval_seeds)
            log(f"{task} {stage}: success {res['successes']}/{res['seeds']}, mean {res['mean_steps']:.0f} steps")
            tc["success"][stage] = res
            path = checkpoint_path(task, stage, out)
            save_checkpoint(path, model, dict(meta, stage=stage, training_steps=tc["stage_steps"][stage], success=res))
            tc["checkpoint_sha256"][stage] = sha256(path)
        config["tasks"][task] = tc
        config_path.write_text(json.dumps(config, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
