"""`wsp study ordering`: whether the suites put models of a known order in that order (docs/analyses.md), from
score reports and their release. The reports are given in the known order, worst first: checkpoints of one
training run by step, or of one recipe by training-set size.

Per platform and suite: Kendall's τ-b between the known order and the models' suite scores (each computed as the
report computes it: the instance mean, within primitive first on T5), with a 95 % bootstrap CI from resampling
the instances every report scored, the same draw for every model (within groups on T5), and whether the scores are
strictly in order. Per platform, the same for Overall (the mean of the suites every report has), each suite
resampled on its own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_eval.release_format import load_release, split_config
from wsp_eval.studies import StudyError
from wsp_eval.studies.analysis_inputs import config_records, load_report, model, pyplot, write_json
from wsp_eval.studies.stats import BOOTSTRAP, SEED, interval_text
from wsp_eval.suites import SCORERS

OUTPUTS = ("ordering.json", "ordering.png")


def kendall_tau(x, y) -> float | None:
    """Kendall's τ-b of paired values (ties count in neither direction); None when either side is constant."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    i, j = np.triu_indices(len(x), 1)
    dx, dy = np.sign(x[i] - x[j]), np.sign(y[i] - y[j])
    denom = np.sqrt(np.count_nonzero(dx) * np.count_nonzero(dy))
    return float((dx * dy).sum() / denom) if denom else None


class SuiteScores:
    """The scores of every model (rows, in the known order) on the instances all of them scored (columns) of one
    config, with the suite's grouping; `score(columns)` is each model's suite score over those columns."""

    def __init__(self, suite: str, scores: np.ndarray, groups: list[str]):
        self.balanced = SCORERS[suite].BALANCED
        self.scores, self.groups = scores, np.asarray(groups)

    def score(self, columns: np.ndarray | None = None) -> np.ndarray:
        s = self.scores if columns is None else self.scores[:, columns]
        if not self.balanced:
            return s.mean(axis=1)
        g = self.groups if columns is None else self.groups[columns]
        return np.mean([s[:, g == k].mean(axis=1) for k in dict.fromkeys(g)], axis=0)

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """One bootstrap draw of columns (within groups when the suite is balanced)."""
        if not self.balanced:
            return rng.integers(0, self.scores.shape[1], self.scores.shape[1])
        parts = [np.flatnonzero(self.groups == k) for k in dict.fromkeys(self.groups)]
        return np.concatenate([p[rng.integers(0, len(p), len(p))] for p in parts])


def tau_entry(order: np.ndarray, point: np.ndarray, draws: list[np.ndarray]) -> dict:
    taus = [t for d in draws if (t := kendall_tau(order, d)) is not None]
    return {"scores": [float(v) for v in point], "kendall_tau": kendall_tau(order, point),
            "kendall_tau_ci": [float(v) for v in np.percentile(taus, [2.5, 97.5])] if taus else None,
            "in_order": bool(np.all(np.diff(point) > 0))}


def run(release: Path, reports: list[Path], out: Path) -> dict:
    """τ per platform and suite, and of Overall, for the reports in their known order; writes OUTPUTS."""
    if len(reports) < 3:
        raise StudyError(f"an ordering needs at least three reports in their known order (got {len(reports)})")
    names = [model(load_report(p)) for p in reports]
    per_config: dict[str, dict[str, tuple[list[dict], dict]]] = {}
    for suite in sorted({split_config(c)[0] for c in load_release(release).get("configs", {})} & set(SCORERS)):
        for config, report, recs, rows in config_records(release, reports, suite):
            per_config.setdefault(config, {})[model(report)] = (recs, rows)
    result: dict = {"release": str(release), "models": names, "platforms": {}}
    order = np.arange(len(names), dtype=float)
    rng = np.random.default_rng(SEED)
    for config, by_model in sorted(per_config.items()):
        if len(by_model) < len(names):
            continue  # a config some report did not score: not comparable
        suite, platform = split_config(config)
        common = sorted(set.intersection(*({r["instance_id"] for r in recs} for recs, _ in by_model.values())))
        rows = next(iter(by_model.values()))[1]
        by_id = {m: {r["instance_id"]: r["score"] for r in by_model[m][0]} for m in names}
        scores = np.array([[by_id[m][i] for i in common] for m in names])
        suite_scores = SuiteScores(suite, scores, SCORERS[suite].groups([rows[i] for i in common]))
        samples = np.array([suite_scores.score(suite_scores.draw(rng)) for _ in range(BOOTSTRAP)])
        p = result["platforms"].setdefault(platform, {"suites": {}, "samples": {}})
        p["suites"][suite] = {"config": config, "n": len(common), **tau_entry(order, suite_scores.score(), samples)}
        p["samples"][suite] = samples
    if not result["platforms"]:
        raise StudyError(f"no config of {release} is scored by every report given")
    for p in result["platforms"].values():
        samples = p.pop("samples")
        point = np.mean([s["scores"] for s in p["suites"].values()], axis=0)
        p["overall"] = {"suites": sorted(p["suites"]), **tau_entry(order, point, list(np.mean(list(samples.values()),
                                                                                               axis=0)))}
    write_json(out, OUTPUTS[0], result)
    figure(result, out / OUTPUTS[1])
    return result


def figure(result: dict, path: Path) -> None:
    plt = pyplot()
    platforms = sorted(result["platforms"])
    fig, axes = plt.subplots(1, len(platforms), figsize=(5.5 * len(platforms), 4), squeeze=False)
    x = np.arange(len(result["models"]))
    for ax, platform in zip(axes[0], platforms):
        p = result["platforms"][platform]
        for suite, s in [*sorted(p["suites"].items()), ("overall", p["overall"])]:
            tau = "—" if s["kendall_tau"] is None else f"{s['kendall_tau']:.2f}"
            ax.plot(x, s["scores"], marker="o", lw=2.5 if suite == "overall" else 1.2,
                    color="black" if suite == "overall" else None, label=f"{suite.upper()} (τ {tau})")
        ax.set_xticks(x, result["models"], rotation=20, fontsize=7)
        ax.set_title(f"{platform}: known order, worst first")
        ax.set_ylabel("score")
        ax.set_ylim(-5, 105)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(result: dict) -> str:
    lines = [f"models in their known order: {' < '.join(result['models'])}", "",
             "| platform | suite | n | scores in that order | Kendall τ [95 % CI] | in order |",
             "|---|---|---|---|---|---|"]
    for platform, p in sorted(result["platforms"].items()):
        for suite, s in [*sorted(p["suites"].items()), ("overall", p["overall"])]:
            tau = "—" if s["kendall_tau"] is None else f"{s['kendall_tau']:.2f}"
            n = s.get("n", "")
            lines.append(f"| {platform} | {suite.upper() if suite != 'overall' else 'Overall'} | {n} | "
                         f"{', '.join(f'{v:.1f}' for v in s['scores'])} | {tau}{interval_text(s['kendall_tau_ci'])} | "
                         f"{'yes' if s['in_order'] else 'no'} |")
    return "\n".join(lines) + "\n"
