"""`wsp study idm-train` and `wsp study idm`: an inverse-dynamics evaluator for comparison with the paper's Table 4b
(docs/analyses.md). A baseline of the evaluation method, never a suite score.

The model is a closed-form ridge regression, not a network: from the optical flow between frames t and t + 1 to
the native action applied at t. Features: OpenCV DIS flow (preset MEDIUM) between the two frames resized to
`SIZE`² grey, averaged over each cell of a `GRID`×`GRID` grid (x and y components), standardised by the training
mean and SD, and a constant. Weights W = (XᵀX + λI)⁻¹ XᵀY with λ = `RIDGE` (the constant unpenalised). No random
state: training twice gives the same checkpoint. Trained on a platform's `train_<platform>` split; the checkpoint
is a small JSON (`MAX_CHECKPOINT_BYTES`).

Evaluation: **Micro-MSE**, the mean over matched timesteps and action dimensions of (predicted − true action)², per
stream kind, on the simulator references: `expert` (T3's expert group and T1's unperturbed originals),
`policy_early` (T3's early checkpoint) and `cross_task` (T2's replays), with each kind's ratio to the expert's; with
`--submission`, the same on the submission's generated videos (its first seed) of those episodes, over the configs it
was made for (its `submission.json`'s "configs", default all).
"""

from __future__ import annotations

import glob
import json
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval.reference import episodes, reference_frames
from wsp_eval.release_format import INSTANCES, format_problem, load_release, split_config
from wsp_eval.studies import StudyError
from wsp_eval.studies.analysis_inputs import pyplot, write_json
from wsp_eval.submission import named_configs
from wsp_eval.video import VideoError, read_video

SIZE = 64
GRID = 4
RIDGE = 1.0
MAX_CHECKPOINT_BYTES = 64 * 1024
KINDS = ("expert", "policy_early", "cross_task")
OUTPUTS = ("idm.json", "idm.png")
PACKAGED = Path(__file__).parent / "weights"  # idm_<platform>.json: the checkpoints `wsp study idm` uses by default


def features(frames: np.ndarray) -> np.ndarray:
    """(T, H, W, 3) uint8 RGB → (T − 1, 2·GRID²) pooled DIS flow of each adjacent pair."""
    cv2.setNumThreads(1)
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    grey = [cv2.resize(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), (SIZE, SIZE), interpolation=cv2.INTER_AREA)
            for f in frames]
    out = []
    for a, b in zip(grey[:-1], grey[1:]):
        flow = dis.calc(a, b, None)
        cells = flow.reshape(GRID, SIZE // GRID, GRID, SIZE // GRID, 2).mean(axis=(1, 3))
        out.append(cells.ravel())
    return np.array(out, np.float64).reshape(-1, 2 * GRID * GRID)


def actions(config_dir: Path) -> dict[int, np.ndarray]:
    """episode_index → its (T, D) native action stream (frame t: the action applied after observation t)."""
    parts: dict[int, list] = {}
    for path in sorted(glob.glob(str(config_dir / "data" / "*" / "*.parquet"))):
        t = pq.read_table(path, columns=["episode_index", "frame_index", "action"]).to_pydict()
        for e, f, a in zip(t["episode_index"], t["frame_index"], t["action"]):
            parts.setdefault(e, []).append((f, a))
    return {e: np.array([a for _, a in sorted(v)], float) for e, v in parts.items()}


def pairs(frames: np.ndarray, stream: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Features of the adjacent frame pairs and the actions between them, over their common length."""
    n = min(len(frames), len(stream)) - 1
    if n < 1:
        return np.zeros((0, 2 * GRID * GRID)), np.zeros((0, stream.shape[1]))
    return features(frames[:n + 1]), stream[:n]


def train(release: Path, platform: str) -> dict:
    """The ridge IDM of `platform` from the release's `train_<platform>` split."""
    config_dir = Path(release) / f"train_{platform}"
    if not (config_dir / INSTANCES).is_file():
        raise StudyError(f"{release}: no train_{platform} split to train an IDM on")
    stream = actions(config_dir)
    xs, ys = zip(*(pairs(reference_frames(config_dir, e), stream[e]) for e in sorted(stream)))
    x, y = np.concatenate(xs), np.concatenate(ys)
    mean, sd = x.mean(axis=0), x.std(axis=0) + 1e-9
    design = np.hstack([(x - mean) / sd, np.ones((len(x), 1))])
    penalty = RIDGE * np.eye(design.shape[1])
    penalty[-1, -1] = 0.0
    weights = np.linalg.solve(design.T @ design + penalty, design.T @ y)
    names = json.loads((config_dir / "meta" / "info.json").read_text())["features"]["action"].get("names")
    return {"platform": platform, "action_names": names, "samples": len(x), "episodes": len(stream),
            "features": {"size": SIZE, "grid": GRID}, "ridge": RIDGE, "mean": mean.tolist(), "sd": sd.tolist(),
            "weights": weights.tolist(),
            "train_mse": float(np.mean((design @ weights - y) ** 2))}


def save(checkpoint: dict, path: Path) -> None:
    text = json.dumps(checkpoint, separators=(",", ":"))
    if len(text) > MAX_CHECKPOINT_BYTES:
        raise StudyError(f"{path}: checkpoint of {len(text)} bytes is over the {MAX_CHECKPOINT_BYTES} limit")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(text)


def load(path: Path) -> dict:
    try:
        c = json.loads(Path(path).read_text())
        _ = c["platform"], c["mean"], c["sd"], c["weights"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise StudyError(f"{path}: not an IDM checkpoint of `wsp study idm-train` ({type(e).__name__}: {e})") from None
    return c


def predict(checkpoint: dict, x: np.ndarray) -> np.ndarray:
    design = np.hstack([(x - np.array(checkpoint["mean"])) / np.array(checkpoint["sd"]), np.ones((len(x), 1))])
    return design @ np.array(checkpoint["weights"])


def streams(release: Path, platform: str) -> dict[str, list[tuple[str, dict]]]:
    """kind → [(config, episode row)] of the scored references of each KINDS on the platform."""
    out: dict[str, list[tuple[str, dict]]] = {k: [] for k in KINDS}
    for config in sorted(load_release(release).get("configs", {})):
        suite, p = split_config(config)
        config_dir = Path(release) / config
        if p != platform or not (config_dir / INSTANCES).is_file():
            continue
        for e in episodes(config_dir).values():
            group = json.loads(e["wsp.intervention"] or "{}").get("source_group")
            kind = {("t3", "expert"): "expert", ("t3", "policy_early"): "policy_early"}.get((suite, group))
            if suite == "t1" and e["wsp.role"] == "original":
                kind = "expert"
            if suite == "t2" and e["wsp.role"] == "reference":
                kind = "cross_task"
            if kind:
                out[kind].append((config, e))
    return out


def first_seed(submission: Path) -> int:
    """The first generation seed `submission.json` lists; StudyError naming the file when there is none."""
    path = Path(submission) / "submission.json"
    try:
        return int(json.loads(path.read_text())["seeds"][0])
    except (OSError, ValueError, KeyError, TypeError, IndexError) as e:
        raise StudyError(f"{path}: not a submission's manifest with seeds ({type(e).__name__}: {e})") from None


def evaluate(release: Path, checkpoint: dict, submission: Path | None = None) -> dict:
    """Micro-MSE per kind on the references (and, with `submission`, on its generated videos of the configs it was
    made for; None where it has none), and the ratios."""
    platform = checkpoint["platform"]
    seed = None if submission is None else first_seed(submission)
    covered = set() if submission is None else set(named_configs(submission, release))
    result: dict = {"platform": platform, "kinds": {}}
    found = streams(release, platform)
    if not any(found.values()):
        raise StudyError(f"{release}: no T1, T2 or T3 reference of {platform} for its IDM checkpoint to read")
    cached: dict[str, dict] = {}
    for kind, items in found.items():
        errors: dict[str, list[np.ndarray]] = {"reference": [], "generated": []}
        for config, e in items:
            config_dir = Path(release) / config
            stream = cached.setdefault(config, actions(config_dir))[e["episode_index"]]
            x, y = pairs(reference_frames(config_dir, e["episode_index"]), stream)
            errors["reference"].append(((predict(checkpoint, x) - y) ** 2).ravel())
            if config in covered:
                path = Path(submission) / config / e["wsp.episode_id"] / f"seed{seed}.mp4"
                if not path.is_file():
                    raise StudyError(f"{path}: missing (the IDM reads the submission's seed {seed} of every episode)")
                try:
                    x, y = pairs(read_video(path)[0], stream)
                except VideoError as e:
                    raise StudyError(str(e)) from None
                errors["generated"].append(((predict(checkpoint, x) - y) ** 2).ravel())
        result["kinds"][kind] = {"episodes": len(items), **{
            f"{side}_micro_mse": float(np.concatenate(v).mean()) if v else None for side, v in errors.items()
            if side == "reference" or submission is not None}}
        if submission is not None:
            result["kinds"][kind]["generated_episodes"] = len(errors["generated"])
    expert = result["kinds"]["expert"].get("reference_micro_mse")
    for kind, k in result["kinds"].items():
        k["reference_ratio_to_expert"] = (k["reference_micro_mse"] / expert if expert and k["reference_micro_mse"]
                                          is not None else None)
    return result


def packaged(release: Path) -> list[Path]:
    """The packaged checkpoints of the platforms the release holds."""
    platforms = {split_config(c)[1] for c in load_release(release).get("configs", {})}
    found = [PACKAGED / f"idm_{p}.json" for p in sorted(platforms) if (PACKAGED / f"idm_{p}.json").is_file()]
    if not found:
        raise StudyError(f"{release}: no packaged IDM checkpoint for {', '.join(sorted(platforms))} (train one with "
                         "`wsp study idm-train` and pass it with --checkpoint)")
    return found


def run(release: Path, checkpoints: list[Path] | None, out: Path, submission: Path | None = None) -> dict:
    """Every checkpoint's evaluation on the release (default: the packaged ones); writes idm.json into `out`."""
    meta = load_release(release)
    if (problem := format_problem(release, meta)) is not None:
        raise StudyError(problem)
    checkpoints = checkpoints or packaged(release)
    result = {"release": str(release), "submission": None if submission is None else str(submission),
              "platforms": {}}
    for path in checkpoints:
        c = load(path)
        result["platforms"][c["platform"]] = {"checkpoint": str(path), **evaluate(release, c, submission)}
    write_json(out, OUTPUTS[0], result)
    figure(result, out / OUTPUTS[1])
    return result


def figure(result: dict, path: Path) -> None:
    plt = pyplot()
    platforms = sorted(result["platforms"])
    fig, axes = plt.subplots(1, len(platforms), figsize=(4.5 * len(platforms), 3.8), squeeze=False)
    for ax, platform in zip(axes[0], platforms):
        kinds = result["platforms"][platform]["kinds"]
        x = np.arange(len(KINDS))
        sides = ["reference"] + (["generated"] if result["submission"] else [])
        for k, side in enumerate(sides):
            values = [np.nan if (v := kinds[kind].get(f"{side}_micro_mse")) is None else v for kind in KINDS]
            ax.bar(x + (k - (len(sides) - 1) / 2) * 0.38, values, 0.38,
                   label="simulator references" if side == "reference" else "generated videos")
        ax.set_xticks(x, KINDS)
        ax.set_title(f"{platform}: IDM Micro-MSE (lower is better)", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(result: dict) -> str:
    def f(x) -> str:
        return "—" if x is None else f"{x:.4g}"

    lines = ["| platform | stream | episodes | IDM Micro-MSE on references | × expert | on generated videos |",
             "|---|---|---|---|---|---|"]
    for platform, p in sorted(result["platforms"].items()):
        for kind, k in p["kinds"].items():
            some = k.get("generated_episodes", k["episodes"])
            of = f" ({some} of {k['episodes']})" if 0 < some < k["episodes"] else ""
            lines.append(f"| {platform} | {kind} | {k['episodes']} | {f(k['reference_micro_mse'])} | "
                         f"{f(k['reference_ratio_to_expert'])} | {f(k.get('generated_micro_mse'))}{of} |")
    return "\n".join(lines) + "\n"
