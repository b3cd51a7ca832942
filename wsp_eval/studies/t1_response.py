"""`wsp study t1-response`: T1's perturbation–response curves (docs/analyses.md), from score reports and their
release.

Per T1 instance and perturbed variant v ∈ {small, large} of magnitude m: the model's response D(ĝ⁰, ĝᵛ) (mean over
seeds; the report's T1 evidence `d_os`, `d_ol`) and the simulator's D(x⁰, xᵛ) (the instance row's `d_os`,
`d_ol`). Each is made relative by dividing by its mean over the variants of the same task (0 where that mean is
0: no response at all), so models of different pixel-error scale share one axis. Per magnitude (the release's
values: the spec's five) the mean relative response of model and simulator with 95 % bootstrap CIs over the
instances, pooled over the config's tasks and per task. The **compression factor** is the least-squares slope
of the model's relative response on the simulator's over all variants, with a 95 % bootstrap CI over instances
(both variants of an instance resampled together): 1 follows the simulator's scaling, 0 responds the same to
every perturbation, between them the response is compressed.

Which side of the simulator's ratio the model falls on, per instance: T1's own r = D(ĝ⁰, ĝˢ)/D(ĝ⁰, ĝˡ) (mean over
seeds) against r* = D(x⁰, xˢ)/D(x⁰, xˡ). r < r* under-expresses the small perturbation (a dead zone), r > r*
answers both alike (compressed toward r = 1), no response at all has no r. The shares of each and the median
r / r* with a 95 % bootstrap CI over instances: T1 scores r / r* below r*, and (1 − r)/(1 − r*) above it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_eval.studies import StudyError, suite_configs
from wsp_eval.studies.analysis_inputs import instance_rows, load_reports, model, pyplot, records, write_json
from wsp_eval.studies.stats import bootstrap_ci, interval_text, mean_ci, slope

OUTPUTS = ("t1_response.json", "t1_response.png")
VARIANTS = (("small", "d_os", "magnitude_small"), ("large", "d_ol", "magnitude_large"))


def variants(report: dict, release: Path, config: str) -> list[dict]:
    """One entry per (instance, variant): task, instance, magnitude, model and simulator distance."""
    rows = instance_rows(release, config)
    out = []
    for rec in records(report, "t1").get(config, []):
        seeds = [s for s in rec["seeds"] if not s.get("missing")]
        if any("d_os" not in s for s in seeds):
            raise StudyError(f"{report['path']}: {rec['instance_id']} holds no generated distances d_os, d_ol "
                             "(score the submission again with this version of `wsp score`)")
        row = rows.get(rec["instance_id"])
        if row is None:
            raise StudyError(f"{report['path']}: {rec['instance_id']} is not in {release / config}")
        ratios = [s["r"] for s in seeds if s["r"] is not None]  # T1's r as scored (None: no large response)
        for variant, key, magnitude in VARIANTS:
            out.append({"instance_id": rec["instance_id"], "task": row["task"], "variant": variant,
                        "magnitude": round(float(row[magnitude]), 9), "simulator": float(row[key]),
                        "model": float(np.mean([s[key] for s in seeds])) if seeds else 0.0,
                        "r": float(np.mean(ratios)) if ratios else None, "r_star": float(row["r_star"])})
    return out


def sides(entries: list[dict]) -> dict:
    """Per instance r against r*: the shares with r < r* (small under-expressed), r > r* (compressed) and no
    response, and the median r / r* with its bootstrap CI over the instances that respond."""
    first = {e["instance_id"]: e for e in entries if e["variant"] == "small"}
    n = len(first)
    ratio = np.array([e["r"] / e["r_star"] for e in first.values() if e["r"] is not None])
    return {"instances": n, "under": float((ratio < 1).sum() / n), "compressed": float((ratio > 1).sum() / n),
            "no_response": float((n - len(ratio)) / n),
            "median_ratio": float(np.median(ratio)) if len(ratio) else None,
            "median_ratio_ci": bootstrap_ci(lambda i: float(np.median(ratio[i])), len(ratio))}


def relative(entries: list[dict]) -> None:
    """Adds `model_relative` and `simulator_relative`: each distance over its mean within the entry's task."""
    for task in {e["task"] for e in entries}:
        mine = [e for e in entries if e["task"] == task]
        for side in ("model", "simulator"):
            mean = float(np.mean([e[side] for e in mine]))
            for e in mine:
                e[f"{side}_relative"] = e[side] / mean if mean > 0 else 0.0


def compression(entries: list[dict]) -> dict:
    """The slope of model on simulator relative response, with its bootstrap CI over instances."""
    ids = sorted({e["instance_id"] for e in entries})
    by_id = {i: [e for e in entries if e["instance_id"] == i] for i in ids}

    def fit(index: np.ndarray) -> float | None:
        chosen = [e for k in index for e in by_id[ids[k]]]
        return slope([e["simulator_relative"] for e in chosen], [e["model_relative"] for e in chosen])

    return {"slope": fit(np.arange(len(ids))), "ci": bootstrap_ci(fit, len(ids)), "instances": len(ids)}


def curve(entries: list[dict]) -> list[dict]:
    """Per magnitude: mean relative response of model and simulator with CIs."""
    out = []
    for m in sorted({e["magnitude"] for e in entries}):
        at = [e for e in entries if e["magnitude"] == m]
        out.append({"magnitude": m, "model": mean_ci([e["model_relative"] for e in at]),
                    "simulator": mean_ci([e["simulator_relative"] for e in at])})
    return out


def analyse(entries: list[dict]) -> dict:
    """Curves and compression, pooled and per task, with every variant's values."""
    relative(entries)

    def both(chosen: list[dict]) -> dict:
        return {"curve": curve(chosen), "compression": compression(chosen), "sides": sides(chosen)}

    tasks = sorted({e["task"] for e in entries})
    return {"pooled": both(entries), "per_task": {t: both([e for e in entries if e["task"] == t]) for t in tasks},
            "variants": entries}


def run(release: Path, reports: list[Path], out: Path) -> dict:
    """Every report's T1 curves per T1 config of the release; writes OUTPUTS into `out`."""
    configs = suite_configs(release, "t1")
    result = {"release": str(release), "configs": {}}
    for report in load_reports(reports, release):
        for config in configs:
            entries = variants(report, release, config)
            if entries:
                result["configs"].setdefault(config, {})[model(report)] = analyse(entries)
    if not result["configs"]:
        raise StudyError(f"no report given holds a T1 instance of {release}")
    write_json(out, OUTPUTS[0], result)
    figure(result, out / OUTPUTS[1])
    return result


def figure(result: dict, path: Path) -> None:
    """Per config: the relative response per magnitude (top) and each instance's r against r* (bottom, log axes)."""
    plt = pyplot()
    configs = sorted(result["configs"])
    fig, axes = plt.subplots(2, len(configs), figsize=(5 * len(configs), 8), squeeze=False)
    for top, bottom, config in zip(axes[0], axes[1], configs):
        models = result["configs"][config]
        first = next(iter(models.values()))["pooled"]["curve"]
        top.errorbar([p["magnitude"] for p in first], [p["simulator"]["mean"] for p in first],
                     yerr=_yerr([p["simulator"] for p in first]), color="black", marker="s", capsize=3,
                     label="simulator", linewidth=2)
        plotted = False
        for name, a in models.items():
            c = a["pooled"]["curve"]
            k = a["pooled"]["compression"]["slope"]
            line = top.errorbar([p["magnitude"] for p in c], [p["model"]["mean"] for p in c],
                                yerr=_yerr([p["model"] for p in c]), marker="o", capsize=3,
                                label=f"{name} (slope {_f(k)})")
            pairs = [(e["r_star"], e["r"]) for e in a["variants"]
                     if e["variant"] == "small" and e["r"] is not None and e["r"] > 0]
            if pairs:
                bottom.scatter(*zip(*pairs), s=14, color=line[0].get_color(), alpha=0.8,
                               label=f"{name} (median r/r* {_f(a['pooled']['sides']['median_ratio'])})")
                plotted = True
        top.set_title(config)
        top.set_xlabel("perturbation magnitude (native units)")
        top.set_ylabel("relative response D / task mean")
        top.legend(fontsize=7)
        if not plotted:
            bottom.text(0.5, 0.5, "no model responds", ha="center", transform=bottom.transAxes)
            continue
        bottom.set_xscale("log")
        bottom.set_yscale("log")
        lo, hi = min(bottom.get_xlim()[0], bottom.get_ylim()[0]), max(bottom.get_xlim()[1], bottom.get_ylim()[1])
        bottom.plot([lo, hi], [lo, hi], color="black", linewidth=1, label="r = r*")
        bottom.set_xlabel("r* (simulator)")
        bottom.set_ylabel("r (model): below the line the small perturbation is under-expressed", fontsize=8)
        bottom.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _yerr(stats: list[dict]) -> np.ndarray:
    lo = [s["mean"] - s["ci"][0] if s["ci"] else 0.0 for s in stats]
    hi = [s["ci"][1] - s["mean"] if s["ci"] else 0.0 for s in stats]
    return np.clip(np.array([lo, hi]), 0, None)


def _f(x: float | None) -> str:
    return "—" if x is None else f"{x:.2f}"


def markdown(result: dict) -> str:
    lines = ["| config | model | compression slope [95 % CI] | r < r* | r > r* | no response | median r / r* [95 % CI] "
             "| instances |", "|---|---|---|---:|---:|---:|---|---:|"]
    for config, models in sorted(result["configs"].items()):
        for name, a in models.items():
            k, s = a["pooled"]["compression"], a["pooled"]["sides"]
            lines.append(f"| {config} | {name} | {_f(k['slope'])}{interval_text(k['ci'])} | {s['under']:.0%} | "
                         f"{s['compressed']:.0%} | {s['no_response']:.0%} | {_f(s['median_ratio'])}"
                         f"{interval_text(s['median_ratio_ci'])} | {k['instances']} |")
    return "\n".join(lines) + "\n"
