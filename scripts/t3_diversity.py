"""Evidence that T3's action sources differ: PCA of the arm joint streams per task (gripper excluded) and a
table of per-source speed, smoothness and success, from a built `t3_<platform>` config.

    .venv/bin/python scripts/t3_diversity.py worldsimprobe/t3_maniskill --out docs/t3_diversity

Writes `<out>.png` (one PCA panel per task, a point per episode, coloured by source group) and `<out>.md`
(the table). Per source group, over its episodes: steps (length at 20 Hz), mean arm joint speed (rad/s),
jerk (RMS third time-derivative of the 7 arm joint targets, rad/s³), success (fraction of references whose
last frame succeeds), and the mean distance of its streams from the expert's of the same group (RMS rad over
time-normalised samples).
"""

from __future__ import annotations

import argparse
import glob
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

ARM = 7
SAMPLES = 50  # time-normalised samples per stream for PCA and distances


def episode_actions(config_dir: Path) -> dict[int, np.ndarray]:
    """episode_index → (T, 8) action stream (the last frame repeats the last action, dropped here)."""
    out: dict[int, list] = {}
    for path in sorted(glob.glob(str(config_dir / "data" / "*" / "*.parquet"))):
        t = pq.read_table(path, columns=["episode_index", "frame_index", "action"]).to_pydict()
        for e, f, a in zip(t["episode_index"], t["frame_index"], t["action"]):
            out.setdefault(e, []).append((f, a))
    return {e: np.array([a for _, a in sorted(v)], np.float64)[:-1] for e, v in out.items()}


def resample(stream: np.ndarray, n: int = SAMPLES) -> np.ndarray:
    t = np.linspace(0, 1, len(stream))
    return np.stack([np.interp(np.linspace(0, 1, n), t, stream[:, j]) for j in range(stream.shape[1])], axis=1)


def stats(stream: np.ndarray, fps: float) -> dict[str, float]:
    arm = stream[:, :ARM]
    speed = np.abs(np.diff(arm, axis=0)).mean() * fps if len(arm) > 1 else 0.0
    jerk = np.sqrt((np.diff(arm, n=3, axis=0) * fps ** 3) ** 2).mean() if len(arm) > 3 else 0.0
    return {"steps": float(len(stream)), "speed": float(speed), "jerk": float(jerk)}


def main(argv: list[str] | None = None) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("config_dir", type=Path)
    p.add_argument("--out", type=Path, required=True, help="output stem (writes .png and .md)")
    args = p.parse_args(argv)
    rows = pq.read_table(args.config_dir / "instances.parquet").to_pylist()
    actions = episode_actions(args.config_dir)
    fps = float(rows[0]["fps"])
    order = list(dict.fromkeys(r["source_group"] for r in rows))
    per: dict[str, list[dict]] = {g: [] for g in order}
    expert = {(r["task"], r["seed"]): actions[r["episode_indices"][0]] for r in rows if r["source_group"] == "expert"}
    for r in rows:
        a = actions[r["episode_indices"][0]]
        s = stats(a, fps) | {"success": float(r["success"][0])}
        ref = expert.get((r["task"], r["seed"]))
        s["from_expert"] = float(np.sqrt(np.mean((resample(a[:, :ARM]) - resample(ref[:, :ARM])) ** 2))) \
            if ref is not None else float("nan")
        per[r["source_group"]].append(s)
    lines = ["| source | episodes | steps | arm speed (rad/s) | jerk (rad/s³) | success | RMS from expert (rad) |",
             "|---|---|---|---|---|---|---|"]
    for g in order:
        m = {k: np.nanmean([s[k] for s in per[g]]) for k in per[g][0]}
        lines.append(f"| {g} | {len(per[g])} | {m['steps']:.0f} | {m['speed']:.3f} | {m['jerk']:.1f} | "
                     f"{m['success']:.2f} | {m['from_expert']:.3f} |")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
    tasks = list(dict.fromkeys(r["task"] for r in rows))
    fig, axes = plt.subplots(1, len(tasks), figsize=(4 * len(tasks), 4), squeeze=False)
    colours = {g: plt.get_cmap("tab10")(i) for i, g in enumerate(order)}
    for ax, task in zip(axes[0], tasks):
        sel = [r for r in rows if r["task"] == task]
        x = np.stack([resample(actions[r["episode_indices"][0]][:, :ARM]).ravel() for r in sel])
        x = x - x.mean(axis=0)
        _, _, vt = np.linalg.svd(x, full_matrices=False)
        xy = x @ vt[:2].T
        for r, (u, v) in zip(sel, xy):
            ax.scatter(u, v, color=colours[r["source_group"]], marker="o" if r["success"][0] else "x", s=30)
        ax.set_title(task)
        ax.set_xlabel("PC 1")
        ax.set_ylabel("PC 2")
    handles = [plt.Line2D([], [], color=c, marker="o", linestyle="", label=g) for g, c in colours.items()]
    fig.legend(handles=handles, loc="lower center", ncol=len(order), frameon=False)
    fig.suptitle("T3 arm joint streams (time-normalised, gripper excluded): PCA per task; x = failed")
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    fig.savefig(args.out.with_suffix(".png"), dpi=110)
    plt.close(fig)
    print("\n".join(lines))
    print(f"wrote {args.out.with_suffix('.png')} and {args.out.with_suffix('.md')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
