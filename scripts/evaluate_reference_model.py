"""Score the reference world model beside the oracle, static and action-blind baselines on a release, and draw
the figures of `docs/guides/reference-model.md`.

    .venv/bin/python scripts/evaluate_reference_model.py --release refeval --out refeval-scores
    # writes <out>/<model>/ (submissions), <out>/reports/<model>/ (reports), <out>/table.md (scores with 95 % CIs
    # per suite and platform), <out>/t1_scatter.png (T1's r against r* per instance and seed) and
    # <out>/strip_<config>.png (generated frames under the reference's)

Resumable: submissions and scoring resume where they stopped.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from wsp_eval.baselines import write_baseline  # noqa: E402
from wsp_eval.generate import episode_contexts, generate  # noqa: E402
from wsp_eval.score import score_submission  # noqa: E402
from wsp_eval.video import read_video  # noqa: E402
from wsp_models.reference import reference_model  # noqa: E402

BASELINES = ("oracle", "static", "action_blind")
MODEL = "reference"
SUITES = ("t1", "t2", "t3", "t4", "t5")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--release", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0],
                    help="generation seeds (default 0: the model and these baselines are deterministic, so every "
                         "seed gives the same videos)")
    ap.add_argument("--workers", type=int, default=2, help="scoring workers")
    args = ap.parse_args()
    generate(reference_model(), args.release, args.out / MODEL, seeds=args.seeds, name=MODEL)
    for name in BASELINES:
        write_baseline(name, args.release, args.out / name, tuple(args.seeds), progress=True)
    reports = {name: score_submission(args.out / name, args.release, args.out / "reports" / name,
                                      workers=args.workers) for name in (MODEL, *BASELINES)}
    table = score_table(reports)
    (args.out / "table.md").write_text(table + "\n")
    print(table)
    t1_scatter(reports[MODEL], args.out / "t1_scatter.png")
    for config in sorted({r["config"] for r in reports[MODEL]["instances"]}):
        if config.startswith(("t2_", "t1_")):
            strip(args.release, args.out / MODEL, config, args.out / f"strip_{config}.png")
    meta = json.loads((args.out / MODEL / "submission.json").read_text())
    print(f"generation: {meta['generation_seconds']:.0f} s on {meta['hardware']}")
    return 0


def score_table(reports: dict[str, dict]) -> str:
    """Markdown: one row per platform × model, each suite's score with its 95 % bootstrap CI, and Overall."""
    head = "| platform | model | " + " | ".join(s.upper() for s in SUITES) + " | Overall |"
    lines = [head, "|" + "---|" * (len(SUITES) + 3)]
    platforms = sorted({p for r in reports.values() for p in r["platforms"]})
    for platform in platforms:
        for name, report in reports.items():
            p = report["platforms"].get(platform)
            if p is None:
                continue
            cells = [_cell(p["suites"].get(s)) for s in SUITES] + [_cell(p["overall"])]
            bold = "**" if name == MODEL else ""
            lines.append(f"| {platform} | {bold}{name}{bold} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _cell(entry: dict | None) -> str:
    if entry is None:
        return "—"
    lo, hi = entry["ci"]
    return f"{entry['score']:.1f} [{lo:.1f}, {hi:.1f}]"


def t1_scatter(report: dict, out: Path) -> None:
    """T1: the model's ratio r = D(ĝ⁰,ĝˢ)/D(ĝ⁰,ĝˡ) against the simulator's r*, one point per instance and seed."""
    fig, ax = plt.subplots(figsize=(4.2, 4), dpi=120)
    for platform, marker in (("maniskill", "o"), ("libero", "s")):
        pts = [(s["r_star"], s["r"]) for rec in report["instances"] if rec["config"] == f"t1_{platform}"
               for s in rec["seeds"] if s.get("r") is not None]
        if pts:
            ax.scatter(*zip(*pts), marker=marker, alpha=0.7, label=platform)
    ax.plot([0, 1], [0, 1], "k--", lw=0.8, label="r = r* (faithful)")
    ax.text(0.97, 0.03, "below: the small perturbation\nunder-expressed (dead zone)", ha="right", va="bottom",
            fontsize=7, transform=ax.transAxes)
    ax.text(0.03, 0.97, "above: responses compressed\ntoward each other (the paper's\nmodels)", ha="left", va="top",
            fontsize=7, transform=ax.transAxes)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("r* (simulator)")
    ax.set_ylabel("r (reference model)")
    ax.set_title("T1: r against r*, per instance and seed", fontsize=10)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, 0.8))
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def strip(release: Path, submission: Path, config: str, out: Path, columns: int = 6) -> None:
    """Reference frames (top) and generated frames (bottom) of the config's first instance, evenly spaced."""
    ctx = next(episode_contexts(release, [config]))
    ref = ctx.frames()
    gen = read_video(submission / config / ctx.episode_id / "seed0.mp4")[0]
    idx = np.linspace(0, min(len(ref), len(gen)) - 1, columns).round().astype(int)
    grid = np.concatenate([np.concatenate([ref[i] for i in idx], axis=1),
                           np.concatenate([gen[i] for i in idx], axis=1)], axis=0)
    fig, ax = plt.subplots(figsize=(columns * 1.3, 2.9), dpi=120)
    ax.imshow(grid)
    ax.set_xticks([(k + 0.5) * ref.shape[2] for k in range(columns)], [f"t={i / ctx.fps:.1f}s" for i in idx])
    ax.set_yticks([ref.shape[1] / 2, ref.shape[1] * 1.5], ["simulator", "reference\nmodel"])
    ax.set_title(f"{config}, {ctx.row['task']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
