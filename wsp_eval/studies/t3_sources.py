"""`wsp study t3-sources`: T3 by action source (docs/analyses.md), from score reports and their release.

Per T3 config and model: the mean score of each source group (`source_group` of the instance rows: expert,
H1–H5, policy_early, policy_late) with a 95 % bootstrap CI; the **policy gap**, late − early policy checkpoint;
and the **operators' spread**, the range (max − min) and the standard deviation of the five operator groups'
means. The gap's and spread's CIs resample each group's instances on their own (`grouped_bootstrap_ci`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_eval.studies import StudyError
from wsp_eval.studies.analysis_inputs import config_records, model, pyplot, write_json
from wsp_eval.studies.stats import grouped_bootstrap_ci, interval_text, mean_ci

OUTPUTS = ("t3_sources.json", "t3_sources.png")
GROUPS = ("expert", "H1", "H2", "H3", "H4", "H5", "policy_early", "policy_late")
OPERATORS = ("H1", "H2", "H3", "H4", "H5")
EARLY, LATE = "policy_early", "policy_late"


def policy_gap(means: dict[str, float]) -> float | None:
    return means[LATE] - means[EARLY] if EARLY in means and LATE in means else None


def operator_range(means: dict[str, float]) -> float | None:
    ops = [means[g] for g in OPERATORS if g in means]
    return float(max(ops) - min(ops)) if len(ops) >= 2 else None


def operator_sd(means: dict[str, float]) -> float | None:
    ops = [means[g] for g in OPERATORS if g in means]
    return float(np.std(ops, ddof=1)) if len(ops) >= 2 else None


def analyse(recs: list[dict], rows: dict[str, dict]) -> dict:
    """Group means, the policy gap and the operators' spread of one model's records of one config."""
    by_group: dict[str, list[float]] = {}
    for r in recs:
        by_group.setdefault(rows[r["instance_id"]]["source_group"], []).append(float(r["score"]))
    groups = {g: np.array(v) for g, v in sorted(by_group.items(), key=lambda x: (_order(x[0]), x[0]))}
    means = {g: float(v.mean()) for g, v in groups.items()}
    out = {"groups": {g: mean_ci(v) for g, v in groups.items()}}
    for name, statistic in (("policy_gap", policy_gap), ("operator_range", operator_range),
                            ("operator_sd", operator_sd)):
        out[name] = {"value": statistic(means), "ci": grouped_bootstrap_ci(groups, statistic)}
    return out


def _order(group: str) -> int:
    return GROUPS.index(group) if group in GROUPS else len(GROUPS)


def run(release: Path, reports: list[Path], out: Path) -> dict:
    """Every report's source-group analysis per T3 config of the release; writes OUTPUTS into `out`."""
    result: dict = {"release": str(release), "configs": {}}
    for config, report, recs, rows in config_records(release, reports, "t3"):
        result["configs"].setdefault(config, {})[model(report)] = analyse(recs, rows)
    if not result["configs"]:
        raise StudyError(f"no report given holds a T3 instance of {release}")
    write_json(out, OUTPUTS[0], result)
    figure(result, out / OUTPUTS[1])
    return result


def figure(result: dict, path: Path) -> None:
    plt = pyplot()
    configs = sorted(result["configs"])
    fig, axes = plt.subplots(1, len(configs), figsize=(6 * len(configs), 4), squeeze=False)
    for ax, config in zip(axes[0], configs):
        models = result["configs"][config]
        width = 0.8 / max(len(models), 1)
        for k, (name, m) in enumerate(models.items()):
            names = list(m["groups"])
            x = np.array([_order(g) for g in names], float) + (k - (len(models) - 1) / 2) * width
            g = [m["groups"][n] for n in names]
            lo = [s["mean"] - s["ci"][0] if s["ci"] else 0.0 for s in g]
            hi = [s["ci"][1] - s["mean"] if s["ci"] else 0.0 for s in g]
            gap = m["policy_gap"]["value"]
            ax.bar(x, [s["mean"] for s in g], width, yerr=np.clip([lo, hi], 0, None), capsize=2,
                   label=f"{name} (late − early {'—' if gap is None else f'{gap:+.1f}'})")
        ax.set_xticks(range(len(GROUPS)), GROUPS, rotation=30, fontsize=8)
        ax.set_title(config)
        ax.set_ylabel("T3 score (RMFA)")
        ax.set_ylim(0, 105)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(result: dict) -> str:
    def cell(x: dict, sign: str = "") -> str:
        v = "—" if x["value"] is None else f"{x['value']:{sign}.1f}"
        return v + interval_text(x["ci"], f"{sign}.1f")

    lines = ["| config | model | late − early [95 % CI] | operators' range [95 % CI] | operators' SD |",
             "|---|---|---|---|---|"]
    for config, models in sorted(result["configs"].items()):
        for name, m in models.items():
            lines.append(f"| {config} | {name} | {cell(m['policy_gap'], '+')} | {cell(m['operator_range'])} | "
                         f"{cell(m['operator_sd'])} |")
    return "\n".join(lines) + "\n"
