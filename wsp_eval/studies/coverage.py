"""`wsp study coverage`: feasible-action coverage, as the paper's Figure 2 (docs/analyses.md), from a release.

Per platform, one task (`--task`, default the task of the platform's T3 config, else its first T2 receiver task):
every rollout of that task's scene in three sets,
- **expert** (task-conditioned): the scripted expert's unperturbed rollouts of the task in any config (`wsp.source`
  starting `scripted_expert`, `wsp.intervention` `{}`: T1's originals, the source rollouts of T2, T4 and T5, the
  training split) and T3's expert group;
- **counterfactual**: T2's scored rollouts whose receiver scene is the task (donor streams of other tasks);
- **source-diverse**: T3's rollouts of the task from the operators H1–H5 and the policy checkpoints.
A rollout's arm motion is its non-gripper joint positions (`observation.state` columns whose name has neither
`finger` nor `gripper`) less those of frame 0, resampled at `SAMPLES` evenly spaced instants of normalised
time and flattened. PCA over the three sets together (centred, SVD) projects them on PC1–2; per set: the area of
its convex hull and the generalised variance (covariance determinant) in PC1–2, and its **reach**, the largest
distance of its points from the expert set's centroid. A set reaches beyond the expert set when its reach exceeds
the expert set's own; `outside_expert_hull` is the share of its points outside the expert set's hull.
"""

from __future__ import annotations

import glob
import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval.reference import episodes
from wsp_eval.release_format import INSTANCES, format_problem, load_release, split_config
from wsp_eval.studies import StudyError
from wsp_eval.studies.analysis_inputs import pyplot, write_json
from wsp_eval.studies.stats import convex_hull, generalised_variance, inside_hull, pca, polygon_area

OUTPUTS = ("coverage.json", "coverage.png")
SAMPLES = 50  # time-normalised samples per rollout, as T2's mismatch and T3's diversity figure
SETS = ("expert", "counterfactual", "source-diverse")
EXPERT_SOURCE = "scripted_expert"
STATE = "observation.state"


def arm_columns(config_dir: Path) -> list[int]:
    """Indices of the non-gripper joints of `observation.state`, from the config's meta/info.json names."""
    path = config_dir / "meta" / "info.json"
    try:
        names = json.loads(path.read_text())["features"][STATE]["names"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise StudyError(f"{path}: no {STATE} names ({type(e).__name__}: {e})") from None
    return [i for i, n in enumerate(names) if "finger" not in n and "gripper" not in n]


def states(config_dir: Path) -> dict[int, np.ndarray]:
    """episode_index → its (T, S) observation.state, in frame order."""
    parts: dict[int, list] = {}
    for path in sorted(glob.glob(str(config_dir / "data" / "*" / "*.parquet"))):
        t = pq.read_table(path, columns=["episode_index", "frame_index", STATE]).to_pydict()
        for e, f, s in zip(t["episode_index"], t["frame_index"], t[STATE]):
            parts.setdefault(e, []).append((f, s))
    return {e: np.array([s for _, s in sorted(v)], float) for e, v in parts.items()}


def motion(state: np.ndarray, arm: list[int], samples: int = SAMPLES) -> np.ndarray:
    """The arm's motion relative to frame 0, resampled at `samples` instants of normalised time, flattened."""
    q = state[:, arm] - state[0, arm]
    t = np.linspace(0, 1, len(q))
    grid = np.linspace(0, 1, samples)
    return np.stack([np.interp(grid, t, q[:, j]) for j in range(q.shape[1])], axis=1).ravel()


def set_of(suite: str, episode: dict) -> str | None:
    """Which of SETS an episode belongs to (None: none of them)."""
    expert = str(episode["wsp.source"]).startswith(EXPERT_SOURCE)
    if suite == "t2" and episode["wsp.role"] == "reference":
        return "counterfactual"
    if suite == "t3":
        return "expert" if expert else "source-diverse"
    return "expert" if expert and episode["wsp.intervention"] in ("{}", "", None) else None


def platform_tasks(release: Path, meta: dict) -> dict[str, dict[str, list[str]]]:
    """platform → suite → its configs' tasks (instance rows' task column, in order of first appearance)."""
    out: dict[str, dict[str, list[str]]] = {}
    for config in sorted(meta.get("configs", {})):
        path = Path(release) / config / INSTANCES
        if not path.is_file():
            continue
        suite, platform = split_config(config)
        tasks = pq.read_table(path, columns=["task"]).column("task").to_pylist()
        out.setdefault(platform, {})[suite] = list(dict.fromkeys(tasks))
    return out


def default_task(suites: dict[str, list[str]]) -> str | None:
    for suite in ("t3", "t2"):
        if suites.get(suite):
            return suites[suite][0]
    return None


def collect(release: Path, platform: str, task: str, configs: list[str]) -> dict[str, list[dict]]:
    """set → [{config, episode_index, motion}] of the task's rollouts on the platform."""
    out: dict[str, list[dict]] = {s: [] for s in SETS}
    for config in configs:
        suite, p = split_config(config)
        config_dir = Path(release) / config
        if p != platform or not (config_dir / INSTANCES).is_file():
            continue
        arm = arm_columns(config_dir)
        meta = {i: e for i, e in episodes(config_dir).items() if e["wsp.task"] == task}
        chosen = {i: s for i, e in meta.items() if (s := set_of(suite, e)) is not None}
        if not chosen:
            continue
        data = states(config_dir)
        for i, s in sorted(chosen.items()):
            if i in data and len(data[i]) >= 2:
                out[s].append({"config": config, "episode_index": int(i), "motion": motion(data[i], arm)})
    return out


def spread(points: np.ndarray, expert_centroid: np.ndarray, expert_hull: np.ndarray) -> dict:
    hull = convex_hull(points) if len(points) else np.zeros((0, 2))
    reach = float(np.linalg.norm(points - expert_centroid, axis=1).max()) if len(points) else None
    outside = ([not inside_hull(p, expert_hull) for p in points] if len(expert_hull) >= 3 and len(points)
               else None)
    return {"n": len(points), "hull_area": polygon_area(hull), "hull": hull.tolist(),
            "generalised_variance": generalised_variance(points), "reach": reach,
            "outside_expert_hull": None if outside is None else float(np.mean(outside))}


def analyse(sets: dict[str, list[dict]]) -> dict:
    """PCA of the three sets together and each set's spread in PC1–2."""
    members = [(s, m) for s in SETS for m in sets[s]]
    if not sets["expert"]:
        raise StudyError("no expert rollout of the task to compare with")
    scores, components, share = pca(np.stack([m["motion"] for _, m in members]))
    xy = {s: np.array([scores[k] for k, (t, _) in enumerate(members) if t == s]).reshape(-1, 2) for s in SETS}
    centroid = xy["expert"].mean(axis=0)
    expert_hull = convex_hull(xy["expert"])
    out = {"explained_variance": [float(x) for x in share], "sets": {}}
    for s in SETS:
        out["sets"][s] = {**spread(xy[s], centroid, expert_hull),
                          "points": [{"config": m["config"], "episode_index": m["episode_index"],
                                      "pc": [float(v) for v in p]} for m, p in zip(sets[s], xy[s])]}
    reach = out["sets"]["expert"]["reach"]
    for s in SETS[1:]:
        r = out["sets"][s]["reach"]
        out["sets"][s]["reaches_beyond_expert"] = None if r is None else bool(r > reach)
    return out


def run(release: Path, out: Path, tasks: list[str] | None = None) -> dict:
    """Coverage of one task per platform of the release; writes OUTPUTS into `out`."""
    meta = load_release(release)
    if (problem := format_problem(release, meta)) is not None:
        raise StudyError(problem)
    by_platform = platform_tasks(release, meta)
    result: dict = {"release": str(release), "samples": SAMPLES, "platforms": {}}
    for platform, suites in sorted(by_platform.items()):
        known = {t for ts in suites.values() for t in ts}
        task = next((t for t in tasks or [] if t in known), None) or default_task(suites)
        if task is None:
            continue
        sets = collect(release, platform, task, sorted(meta["configs"]))
        try:
            result["platforms"][platform] = {"task": task, **analyse(sets)}
        except StudyError as e:
            raise StudyError(f"{release}: {platform} {task}: {e}") from None
    if not result["platforms"]:
        raise StudyError(f"{release}: no T2 or T3 config, so no counterfactual or source-diverse rollout to plot")
    write_json(out, OUTPUTS[0], result)
    figure(result, out / OUTPUTS[1])
    return result


COLOURS = {"expert": "tab:blue", "counterfactual": "tab:orange", "source-diverse": "tab:green"}


def figure(result: dict, path: Path) -> None:
    plt = pyplot()
    platforms = sorted(result["platforms"])
    fig, axes = plt.subplots(1, len(platforms), figsize=(4.5 * len(platforms), 4.2), squeeze=False)
    for ax, platform in zip(axes[0], platforms):
        p = result["platforms"][platform]
        for s in SETS:
            d = p["sets"][s]
            pts = np.array([q["pc"] for q in d["points"]]).reshape(-1, 2)
            ax.scatter(pts[:, 0], pts[:, 1], s=22, color=COLOURS[s], label=f"{s} (n={d['n']})", alpha=0.8)
            if len(d["hull"]) >= 3:
                h = np.array(d["hull"] + d["hull"][:1])
                ax.fill(h[:, 0], h[:, 1], color=COLOURS[s], alpha=0.12)
                ax.plot(h[:, 0], h[:, 1], color=COLOURS[s], linewidth=1)
        ev = p["explained_variance"]
        ax.set_title(f"{platform} {p['task']}", fontsize=9)
        ax.set_xlabel(f"PC1 ({100 * ev[0]:.0f} % of variance)")
        ax.set_ylabel(f"PC2 ({100 * ev[1]:.0f} %)" if len(ev) > 1 else "PC2")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(result: dict) -> str:
    lines = ["| platform | task | PC1+PC2 variance | set | n | hull area | gen. variance | reach | outside expert hull "
             "| beyond expert |", "|---|---|---|---|---|---|---|---|---|---|"]
    for platform, p in sorted(result["platforms"].items()):
        ev = f"{100 * sum(p['explained_variance']):.0f} %"
        for s in SETS:
            d = p["sets"][s]
            gv = "—" if d["generalised_variance"] is None else f"{d['generalised_variance']:.3g}"
            reach = "—" if d["reach"] is None else f"{d['reach']:.3f}"
            beyond = {None: "—", True: "yes", False: "no"}[d.get("reaches_beyond_expert")] if s != "expert" else ""
            share = d["outside_expert_hull"]
            outside = "" if s == "expert" or share is None else f"{100 * share:.0f} %"
            lines.append(f"| {platform} | {p['task']} | {ev} | {s} | {d['n']} | {d['hull_area']:.3g} | {gv} | "
                         f"{reach} | {outside} | {beyond} |")
    return "\n".join(lines) + "\n"
