"""What the paper's analyses read (`docs/analyses.md`): score reports (`wsp score`), checked to be of the release
given, the release's instance rows, and a figure canvas."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq

from wsp_eval.integrity import sha256
from wsp_eval.release_format import INSTANCES, RELEASE_JSON, split_config
from wsp_eval.studies import StudyError, suite_configs


def load_report(path: Path) -> dict:
    """A `wsp score` report (its folder or report.json); StudyError naming the file when it is not one."""
    path = Path(path)
    path = path / "report.json" if path.is_dir() else path
    try:
        report = json.loads(path.read_text())
        _ = report["submission"]["model"], report["instances"], report["release"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise StudyError(f"{path}: not a `wsp score` report ({type(e).__name__}: {e})") from None
    report["path"] = str(path)
    return report


def load_reports(paths: list[Path], release: Path) -> list[dict]:
    """Reports of distinct models, each made against `release` (same release.json SHA-256)."""
    reports = [load_report(p) for p in paths]
    models = [r["submission"]["model"] for r in reports]
    if dupes := sorted({m for m in models if models.count(m) > 1}):
        raise StudyError(f"more than one report of model(s) {', '.join(dupes)}: give one report per model")
    expected = sha256(Path(release) / RELEASE_JSON)
    for r in reports:
        if r["release"].get("release_json_sha256") != expected:
            raise StudyError(f"{r['path']}: scored against another release (release.json sha256 "
                             f"{str(r['release'].get('release_json_sha256'))[:12]}, {release} has {expected[:12]})")
    return reports


def model(report: dict) -> str:
    return str(report["submission"]["model"])


def records(report: dict, suite: str) -> dict[str, list[dict]]:
    """config → the report's instance records of `suite`'s configs."""
    out: dict[str, list[dict]] = {}
    for r in report["instances"]:
        if split_config(r["config"])[0] == suite:
            out.setdefault(r["config"], []).append(r)
    return out


def instance_rows(release: Path, config: str) -> dict[str, dict]:
    """instance_id → its row of the config's instances.parquet."""
    path = Path(release) / config / INSTANCES
    if not path.is_file():
        raise StudyError(f"{path}: missing (the report scored {config}, the release has no such config)")
    return {r["instance_id"]: r for r in pq.read_table(path).to_pylist()}


def pyplot():
    """matplotlib's pyplot on the non-interactive Agg canvas."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_json(out: Path, name: str, result: dict) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text(json.dumps(result, indent=1))
    return out / name


def config_records(release: Path, reports: list[Path], suite: str):
    """(config, report, the report's records of config, the config's instance rows) for every `suite` config of
    `release` and every report (`load_reports`) holding records of it; a record of an instance the release lacks is
    refused. The release's configs are checked before the reports are read."""
    configs = suite_configs(release, suite)
    loaded = load_reports(reports, release)
    for config in configs:
        rows = instance_rows(release, config)
        for report in loaded:
            recs = records(report, suite).get(config, [])
            if missing := [r["instance_id"] for r in recs if r["instance_id"] not in rows]:
                raise StudyError(f"{report['path']}: {missing[0]} is not in {release / config}")
            if recs:
                yield config, report, recs, rows
