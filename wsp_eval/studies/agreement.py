"""`wsp study agreement`: human ratings (`wsp rate`) against score reports (`wsp score`), as the paper measures
its evaluators.

Per rated rollout (model, config, episode, seed): the mean rating over annotators, and the metric's per-seed score
from the report of that model. Reported per suite and overall: Spearman ρ between metric and mean rating (ties
get average ranks), binary agreement (the paper's: a rollout follows the action when its mean rating is ≥ 3; the
metric says so when its score is ≥ `threshold`, default 50 — any value in (0, 100] for the 0/100 suites T4 and
T5), each with a 95 % bootstrap CI over rollouts (`BOOTSTRAP` resamples, seeded), and the annotators' own
agreement (mean pairwise Spearman ρ over the rollouts both rated).
"""

from __future__ import annotations

import json
from collections import defaultdict
from itertools import combinations
from pathlib import Path

import numpy as np

from wsp_eval.release_format import split_config

BOOTSTRAP = 2000
HUMAN_THRESHOLD = 3.0


class AgreementError(RuntimeError):
    """Unreadable ratings or reports, or nothing to compare."""


def _ranks(x: np.ndarray) -> np.ndarray:
    order = np.argsort(x, kind="stable")
    ranks = np.empty(len(x))
    ranks[order] = np.arange(len(x), dtype=float)
    for v in np.unique(x):  # ties: average rank
        tie = x == v
        ranks[tie] = ranks[tie].mean()
    return ranks


def spearman(a, b) -> float | None:
    """Spearman's ρ (average ranks for ties); None when either side is constant or has fewer than 2 values."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 2 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return None
    ra, rb = _ranks(a), _ranks(b)
    return float(np.corrcoef(ra, rb)[0, 1])


def load_ratings(folder: Path) -> list[dict]:
    files = sorted(Path(folder).glob("ratings_*.jsonl"))
    if not files:
        raise AgreementError(f"{folder}: no ratings_*.jsonl (write them with `wsp rate --out {folder}`)")
    out = []
    for path in files:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            try:
                rec = json.loads(line)
                out.append({k: rec[k] for k in ("model", "config", "instance_id", "seed", "rating", "annotator")})
            except (ValueError, KeyError, TypeError):
                raise AgreementError(f"{path}, line {n}: not a rating record") from None
    return out


def load_scores(reports: list[Path]) -> dict[tuple, float]:
    """(model, config, instance_id, seed) → score, from each report's per-instance records."""
    out = {}
    for path in reports:
        path = path / "report.json" if path.is_dir() else path
        try:
            report = json.loads(path.read_text())
            model = report["submission"]["model"]
            for rec in report["instances"]:
                for s in rec["seeds"]:
                    out[(model, rec["config"], rec["instance_id"], int(s["seed"]))] = float(s["score"])
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise AgreementError(f"{path}: not a score report ({type(e).__name__}: {e})") from None
    return out


def _ci(fn, n: int, rng: np.random.Generator) -> list[float] | None:
    values = [v for idx in rng.integers(0, n, (BOOTSTRAP, n)) if (v := fn(idx)) is not None]
    return [float(np.percentile(values, 2.5)), float(np.percentile(values, 97.5))] if values else None


def agreement(ratings: list[dict], scores: dict[tuple, float], threshold: float = 50.0, seed: int = 0) -> dict:
    """The agreement table (module docstring)."""
    per_item: dict[tuple, dict[str, int]] = defaultdict(dict)
    for r in ratings:
        per_item[(r["model"], r["config"], r["instance_id"], int(r["seed"]))][r["annotator"]] = int(r["rating"])
    rows, unmatched = [], 0
    for key, by_annotator in sorted(per_item.items()):
        config = key[1]
        if key not in scores:
            unmatched += 1
            continue
        rows.append({"suite": split_config(config)[0], "config": config, "score": scores[key],
                     "rating": float(np.mean(list(by_annotator.values()))), "ratings": by_annotator})
    if not rows:
        raise AgreementError(f"none of the {len(per_item)} rated rollouts has a score in the reports given (their "
                             "models, configs and seeds must match)")
    rng = np.random.default_rng(seed)
    out = {"rollouts": len(rows), "unmatched": unmatched, "threshold": threshold, "groups": {}}
    for name in ["all"] + sorted({r["suite"] for r in rows}):
        sel = [r for r in rows if name == "all" or r["suite"] == name]
        s = np.array([r["score"] for r in sel])
        h = np.array([r["rating"] for r in sel])
        agree = ((h >= HUMAN_THRESHOLD) == (s >= threshold)).astype(float)
        out["groups"][name] = {
            "n": len(sel), "spearman": spearman(s, h), "spearman_ci95": _ci(lambda i: spearman(s[i], h[i]), len(sel), rng),
            "binary_agreement": float(agree.mean()), "binary_ci95": _ci(lambda i: float(agree[i].mean()), len(sel), rng),
            "human_positive": float((h >= HUMAN_THRESHOLD).mean()), "metric_positive": float((s >= threshold).mean())}
    annotators = sorted({a for r in rows for a in r["ratings"]})
    pairs = []
    for a, b in combinations(annotators, 2):
        both = [r for r in rows if a in r["ratings"] and b in r["ratings"]]
        if (rho := spearman([r["ratings"][a] for r in both], [r["ratings"][b] for r in both])) is not None:
            pairs.append(rho)
    out["annotators"] = annotators
    out["inter_annotator_spearman"] = float(np.mean(pairs)) if pairs else None
    return out


def markdown(result: dict) -> str:
    f = lambda v: "—" if v is None else f"{v:.3f}"  # noqa: E731
    ci = lambda c: "—" if c is None else f"[{c[0]:.3f}, {c[1]:.3f}]"  # noqa: E731
    lines = [f"Agreement with human ratings: {result['rollouts']} rated rollouts, annotators "
             f"{', '.join(result['annotators'])} (mean pairwise ρ {f(result['inter_annotator_spearman'])}); "
             f"binary: mean rating ≥ 3 vs score ≥ {result['threshold']:g}", "",
             "| suite | rollouts | Spearman ρ | 95 % CI | binary agreement | 95 % CI | humans positive | metric positive |",
             "|---|---:|---:|---|---:|---|---:|---:|"]
    for name, g in result["groups"].items():
        lines.append(f"| {name} | {g['n']} | {f(g['spearman'])} | {ci(g['spearman_ci95'])} | "
                     f"{g['binary_agreement']:.3f} | {ci(g['binary_ci95'])} | {g['human_positive']:.2f} | "
                     f"{g['metric_positive']:.2f} |")
    if result["unmatched"]:
        lines += ["", f"{result['unmatched']} rated rollout(s) had no score in the reports given and are left out."]
    return "\n".join(lines) + "\n"
