"""Calibration baselines, found by name: each turns a reference episode into the frames a model would
submit. `oracle` is the reference itself; `static` repeats the first frame."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

import wsp_data
from wsp_data.schema import INSTANCES
from wsp_eval.reference import reference_frames
from wsp_eval.submission import SUBMISSION_JSON, VIDEO_NAME, test_configs
from wsp_eval.video import write_video

Baseline = Callable[[np.ndarray], np.ndarray]


def oracle(reference: np.ndarray) -> np.ndarray:
    return reference


def static(reference: np.ndarray) -> np.ndarray:
    return np.repeat(reference[:1], len(reference), axis=0)


BASELINES: dict[str, Baseline] = {"oracle": oracle, "static": static}


def write_baseline(name: str, release: Path, out: Path, seeds: tuple[int, ...] = (0, 1, 2)) -> int:
    """Write a complete submission of baseline `name` for every scored config; returns videos written."""
    if name not in BASELINES:
        raise KeyError(f"unknown baseline {name!r}; known: {', '.join(BASELINES)}")
    fn, release, out = BASELINES[name], Path(release), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    configs = test_configs(release)
    written = 0
    for config in configs:
        table = pq.read_table(release / config / INSTANCES, columns=["episode_ids", "episode_indices", "fps"])
        for ids, indices, fps in zip(*(table.column(c).to_pylist() for c in ("episode_ids", "episode_indices", "fps"))):
            for episode_id, index in zip(ids, indices):
                frames = fn(reference_frames(release / config, index))
                (out / config / episode_id).mkdir(parents=True, exist_ok=True)
                for s in seeds:
                    write_video(out / config / episode_id / VIDEO_NAME.format(seed=s), frames, fps)
                    written += 1
    meta = {"model": f"baseline:{name}", "benchmark_version": wsp_data.BENCHMARK_VERSION, "seeds": list(seeds),
            "configs": configs, "hardware": "cpu", "generation_seconds": 0}
    (out / SUBMISSION_JSON).write_text(json.dumps(meta, indent=1))
    return written
