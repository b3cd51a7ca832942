"""`wsp study t2-mismatch`: T2 fidelity against receiver–donor motion mismatch (docs/analyses.md), from score
reports and their release.

Per T2 config and model: Spearman's ρ (average ranks for ties) between the instance score and the instance row's
`mismatch`, with a 95 % bootstrap CI over instances, and the decile curve: the mean score per mismatch decile
(T2's report breakdown: rank by mismatch, ties by instance id, decile 1 the smallest) with CIs. Per config, the
mean ρ over the models (the paper averages over its six).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_eval.studies import StudyError
from wsp_eval.studies.agreement import spearman
from wsp_eval.studies.analysis_inputs import config_records, model, pyplot, write_json
from wsp_eval.studies.stats import bootstrap_ci, interval_text, mean_ci
from wsp_eval.suites import t2

OUTPUTS = ("t2_mismatch.json", "t2_mismatch.png")


def analyse(recs: list[dict], rows: dict[str, dict]) -> dict:
    """ρ with its CI and the decile curve of one model's records of one config."""
    recs = sorted(recs, key=lambda r: r["instance_id"])
    mine = [rows[r["instance_id"]] for r in recs]
    score = np.array([r["score"] for r in recs])
    mismatch = np.array([row["mismatch"] for row in mine], float)
    deciles = t2.groups(mine)
    return {"n": len(recs), "spearman": spearman(score, mismatch),
            "spearman_ci": bootstrap_ci(lambda i: spearman(score[i], mismatch[i]), len(recs)),
            "deciles": [{"decile": int(d), **mean_ci(score[[k for k, x in enumerate(deciles) if x == d]])}
                        for d in sorted(set(deciles), key=int)],
            "instances": [{"instance_id": r["instance_id"], "score": r["score"], "mismatch": row["mismatch"]}
                          for r, row in zip(recs, mine)]}


def run(release: Path, reports: list[Path], out: Path) -> dict:
    """Every report's ρ and decile curve per T2 config of the release; writes OUTPUTS into `out`."""
    result: dict = {"release": str(release), "configs": {}}
    for config, report, recs, rows in config_records(release, reports, "t2"):
        result["configs"].setdefault(config, {"models": {}})["models"][model(report)] = analyse(recs, rows)
    if not result["configs"]:
        raise StudyError(f"no report given holds a T2 instance of {release}")
    for entry in result["configs"].values():
        rhos = [m["spearman"] for m in entry["models"].values() if m["spearman"] is not None]
        entry["mean_spearman"] = float(np.mean(rhos)) if rhos else None
    write_json(out, OUTPUTS[0], result)
    figure(result, out / OUTPUTS[1])
    return result


def figure(result: dict, path: Path) -> None:
    plt = pyplot()
    configs = sorted(result["configs"])
    fig, axes = plt.subplots(1, len(configs), figsize=(5 * len(configs), 4), squeeze=False)
    for ax, config in zip(axes[0], configs):
        for name, m in result["configs"][config]["models"].items():
            d = m["deciles"]
            lo = [x["mean"] - x["ci"][0] if x["ci"] else 0.0 for x in d]
            hi = [x["ci"][1] - x["mean"] if x["ci"] else 0.0 for x in d]
            rho = "—" if m["spearman"] is None else f"{m['spearman']:.2f}"
            ax.errorbar([x["decile"] for x in d], [x["mean"] for x in d], yerr=np.clip([lo, hi], 0, None),
                        marker="o", capsize=3, label=f"{name} (ρ {rho})")
        ax.set_title(config)
        ax.set_xlabel("receiver–donor mismatch decile (1 = smallest)")
        ax.set_ylabel("T2 score (RMFA)")
        ax.set_ylim(-5, 105)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(result: dict) -> str:
    lines = ["| config | model | n | Spearman ρ (score, mismatch) [95 % CI] |", "|---|---|---|---|"]
    for config, entry in sorted(result["configs"].items()):
        for name, m in entry["models"].items():
            rho = "—" if m["spearman"] is None else f"{m['spearman']:.3f}"
            lines.append(f"| {config} | {name} | {m['n']} | {rho}{interval_text(m['spearman_ci'], '.3f')} |")
    return "\n".join(lines) + "\n"
