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
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wsp_eval.studies import StudyError, suite_configs
from wsp_eval.studies.analysis_inputs import instance_rows, load_reports, model, pyplot, records, write_json
from wsp_eval.studies.stats import bootstrap_ci, mean_ci, slope

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
        for variant, key, magnitude in VARIANTS:
            out.append({"instance_id": rec["instance_id"], "task": row["task"], "variant": variant,
                        "magnitude": round(float(row[magnitude]), 9), "simulator": float(row[key]),
                        "model": float(np.mean([s[key] for s in seeds])) if seeds else 0.0})
    return out


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
        return {"curve": curve(chosen), "compression": compression(chosen)}

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
    plt = pyplot()
    configs = sorted(result["configs"])
    fig, axes = plt.subplots(1, len(configs), figsize=(5 * len(configs), 4), squeeze=False)
    for ax, config in zip(axes[0], configs):
        models = result["configs"][config]
        first = next(iter(models.values()))["pooled"]["curve"]
        ax.errorbar([p["magnitude"] for p in first], [p["simulator"]["mean"] for p in first],
                    yerr=_yerr([p["simulator"] for p in first]), color="black", marker="s", capsize=3,
                    label="simulator", linewidth=2)
        for name, a in models.items():
            c = a["pooled"]["curve"]
            k = a["pooled"]["compression"]["slope"]
            ax.errorbar([p["magnitude"] for p in c], [p["model"]["mean"] for p in c],
                        yerr=_yerr([p["model"] for p in c]), marker="o", capsize=3, label=f"{name} (slope {_f(k)})")
        ax.set_title(config)
        ax.set_xlabel("perturbation magnitude (native units)")
        ax.set_ylabel("relative response D / task mean")
        ax.legend(fontsize=7)
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
    lines = ["| config | model | compression slope [95 % CI] | instances |", "|---|---|---|---|"]
    for config, models in sorted(result["configs"].items()):
        for name, a in models.items():
            k = a["pooled"]["compression"]
            ci = f" [{k['ci'][0]:.2f}, {k['ci'][1]:.2f}]" if k["ci"] else ""
            lines.append(f"| {config} | {name} | {_f(k['slope'])}{ci} | {k['instances']} |")
    return "\n".join(lines) + "\n"
