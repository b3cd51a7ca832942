"""Train the reference world model (`wsp_models.reference`) for one platform, from a fresh build, in one command.

    .venv/bin/python scripts/train_reference_model.py --platform maniskill --work refmodel
    # builds refmodel/release/train_maniskill (144 expert episodes: 12 per task) unless it is there, trains,
    # writes refmodel/maniskill.pt + .history.json + loss curve, and copies the checkpoint into
    # wsp_models/reference/checkpoints/ (--no-install to keep the shipped one)

Deterministic: the same split, recipe and torch version on the same thread count give the same weights.
Resumable: run the same command again after an interruption (the build resumes, training restarts from its
last saved state). `docs/guides/reference-model.md` has the recipe, the data and what it scores.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from wsp_eval.release_format import INSTANCES  # noqa: E402
from wsp_models.reference.model import CHECKPOINTS  # noqa: E402
from wsp_models.reference.train import Recipe, train  # noqa: E402

# episodes of the training split per platform (it is built with every solved task of the platform, or
# --tasks), and the training recipe per platform
SPLIT = {"maniskill": dict(count=144, tasks=None),
         "libero": dict(count=32, tasks=[
             "libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket",
             "libero_object/pick_up_the_butter_and_place_it_in_the_basket",
             "libero_spatial/pick_up_the_black_bowl_from_table_center_and_place_it_on_the_plate",
             "libero_90/KITCHEN_SCENE1_put_the_black_bowl_on_the_plate"])}
RECIPE = {"maniskill": Recipe(steps=5000), "libero": Recipe(steps=1500, threads=1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platform", choices=sorted(SPLIT), required=True)
    ap.add_argument("--work", type=Path, required=True, help="folder for the split, the training state and outputs")
    ap.add_argument("--steps", type=int, help="training steps (default: the platform's recipe)")
    ap.add_argument("--workers", type=int, default=2, help="build workers")
    ap.add_argument("--no-install", action="store_true", help="do not copy the checkpoint into the package")
    ap.add_argument("--snapshots", type=int, nargs="+", default=[],
                    help="also keep the weights after these steps (multiples of 250), in WORK/step<N>/ "
                         "(scripts/known_ordering.py); the run itself is unchanged")
    args = ap.parse_args()
    release, config = args.work / "release", f"train_{args.platform}"
    split = SPLIT[args.platform]
    if not (release / config / INSTANCES).is_file():
        cmd = [str(Path(sys.executable).with_name("wsp")), "build", "--platform", args.platform, "--suite", "train",
               "--count", str(split["count"]), "--workers", str(args.workers), "--out", str(release)]
        if split["tasks"]:
            cmd += ["--tasks", *split["tasks"]]
        subprocess.run(cmd, check=True)
    recipe = RECIPE[args.platform]
    if args.steps:
        recipe = Recipe(**{**recipe.__dict__, "steps": args.steps})
    ckpt = train(release, config, args.work, recipe, snapshots=args.snapshots)
    plot_history(ckpt.with_suffix(".history.json"), ckpt.with_suffix(".loss.png"))
    if not args.no_install:
        CHECKPOINTS.mkdir(exist_ok=True)
        shutil.copy(ckpt, CHECKPOINTS / ckpt.name)
        shutil.copy(ckpt.with_suffix(".history.json"), CHECKPOINTS / ckpt.with_suffix(".history.json").name)
    print(f"{ckpt} ({ckpt.stat().st_size / 1e6:.1f} MB); loss curve {ckpt.with_suffix('.loss.png')}")
    return 0


def plot_history(history: Path, out: Path) -> None:
    h = json.loads(history.read_text())
    fig, ax = plt.subplots(figsize=(6, 3.2), dpi=120)
    for name, rows in (("train (mean of 25 steps)", h["train"]), ("validation (held-out episodes)", h["val"])):
        if rows:
            ax.plot(*zip(*rows), label=name)
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("weighted L1")
    ax.set_title(f"reference world model, {h['record']['platform']}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
