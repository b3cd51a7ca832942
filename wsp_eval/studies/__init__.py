"""Validity studies of the evaluators (docs/validity.md): they read a release and score references, or stand-ins
made from them, as a submission's videos are scored. Beside them, the paper's analyses (docs/analyses.md:
`coverage`, `t1_response`, `t2_mismatch`, `t3_sources`), which read a release and score reports of it."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from wsp_eval.release_format import INSTANCES, format_problem, load_release, split_config


class StudyError(RuntimeError):
    """A release a study cannot read (no config of its suite, an older format)."""


def suite_configs(release: Path, suite: str) -> list[str]:
    """The release's assembled configs of `suite`, or StudyError saying why there is none to study."""
    meta = load_release(release)
    if (problem := format_problem(release, meta)) is not None:
        raise StudyError(problem)
    configs = sorted(c for c in meta.get("configs", {}) if split_config(c)[0] == suite and (Path(release) / c).is_dir())
    if not configs:
        raise StudyError(f"{release}: no {suite.upper()} config to study")
    return configs


def run_negatives(release: Path, out: Path, suite: str, needs: tuple[str, ...], score_clips: Callable,
                  summarise: Callable[[list[dict]], dict], markdown: Callable[[dict], str], *,
                  configs: list[str] | None, limit: int | None, progress: bool) -> tuple[dict, list[dict]]:
    """A negatives study's run: every variant of up to `limit` instances of each of the suite's configs, scored with
    the default backends (`score_clips(release, config, backends, limit, progress)`), with a progress bar; writes
    `<suite>_negatives.json` (summary and every clip) and `.md`; returns the summary and the clips."""
    import pyarrow.parquet as pq
    from tqdm import tqdm

    from wsp_eval import backends as registry
    from wsp_eval.backends import BackendSpec
    from wsp_eval.console import terminal

    release, out = Path(release), Path(out)
    configs = configs or suite_configs(release, suite)
    backends = registry.make(BackendSpec(), needs)
    total = sum(min(limit or 10**9, pq.read_metadata(release / c / INSTANCES).num_rows) for c in configs)
    bar = tqdm(total=total, desc=f"{suite} negatives", unit="instance", disable=not progress, file=terminal())
    records = [r for c in configs for r in score_clips(release, c, backends, limit, bar.update)]
    bar.close()
    summary = summarise(records)
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{suite}_negatives.json").write_text(json.dumps({"summary": summary, "clips": records}, indent=1))
    (out / f"{suite}_negatives.md").write_text(markdown(summary))
    return summary, records
