"""Scoring throughput per config with the default backends, on one core, as `wsp score` spends it (one instance,
every seed of the submission, the copy check included), with and without the reference caches, against the
floor of merely decoding the submission's videos; and the projected time of the whole benchmark (paper counts of
all three platforms, the submission's seeds).

    .venv/bin/python benchmarks/score_speed.py RELEASE SUBMISSION [RELEASE SUBMISSION ...] [--limit 12] [--workers 2]

Each SUBMISSION should cover every scored config of its RELEASE (e.g. `wsp baseline blur`; the `oracle` is a copy
of the references, which the copy check must decode in full). Per instance it times `score.score_instance`
three ways: with no cache (every reference decoded, tracked, judged, its flows computed), filling the caches
(the first scoring of a release), and reading them (every later scoring: `wsp_eval.flow_cache`,
`wsp_eval.reference_cache`). The caches live where `wsp score` keeps them. A (platform, suite) the releases
do not hold is projected at the same platform's T2 time for T3 (the same RMFA), else at that suite's mean time
over the platforms measured (listed in the output).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval.backends import BackendSpec
from wsp_eval.reference import reference_size
from wsp_eval.release_format import split_config
from wsp_eval.score import Job, backends_for, flow_cache_folder, result_cache_folder, score_instance
from wsp_eval.submission import VIDEO_NAME, test_configs
from wsp_eval.suites import SCORERS
from wsp_eval.video import read_video

# instances per suite and platform (spec §3: ManiSkill / LIBERO / RoboTwin, which ALOHA stands in for)
FULL_COUNTS = {"maniskill": {"t1": 1000, "t2": 1500, "t3": 750, "t4": 1000, "t5": 8 * 295},
               "libero": {"t1": 1000, "t2": 1500, "t3": 1000, "t4": 1000, "t5": 4 * 500},
               "aloha": {"t1": 419, "t2": 1575, "t3": 1000, "t4": 640, "t5": 8 * 233}}
MODES = ("none", "filling", "warm")


def measure(release: Path, submission: Path, config: str, limit: int) -> dict:
    seeds = tuple(json.loads((submission / "submission.json").read_text())["seeds"])
    spec = BackendSpec()
    backends = backends_for(spec, SCORERS[split_config(config)[0]].NEEDS)
    flows = flow_cache_folder(release, spec, backends)
    results = result_cache_folder(release, config, spec, backends)
    rows = pq.read_table(release / config / "instances.parquet").to_pylist()[:limit]
    size = reference_size(release / config)
    times = {m: [] for m in MODES}
    decode = []
    for row in rows:
        t = time.perf_counter()
        for seed in seeds:
            for e in row["episode_ids"]:
                read_video(submission / config / e / VIDEO_NAME.format(seed=seed))
        decode.append(time.perf_counter() - t)
        if flows:  # "filling" starts from empty entries
            for episode in row["episode_indices"]:
                for p in Path(flows, config).glob(f"{episode:06d}_*.npz"):
                    p.unlink()
        if results:
            Path(results, config, f"{row['episode_indices'][0]:06d}.json").unlink(missing_ok=True)
        caches = {"none": (None, None), "filling": (flows, results), "warm": (flows, results)}
        for mode in MODES:
            job = Job(str(release), str(submission), config, row, seeds,
                      flow_cache=str(caches[mode][0]) if caches[mode][0] else None,
                      result_cache=caches[mode][1], size=size)
            t = time.perf_counter()
            score_instance(job, spec)
            times[mode].append(time.perf_counter() - t)
    out = {"config": config, "n": len(rows), "seeds": len(seeds), "decode_floor_s": float(np.mean(decode))}
    out.update({f"{m}_s": float(np.mean(times[m])) for m in MODES})
    out["warm_x_floor"] = out["warm_s"] / out["decode_floor_s"]
    return out


def project(results: list[dict], mode: str, workers: int) -> tuple[float, list[str]]:
    """Seconds for every instance of the paper's counts on `workers` cores, and the (platform, suite) pairs
    projected from other platforms' times."""
    measured = {split_config(r["config"])[::-1]: r[f"{mode}_s"] for r in results}
    total, borrowed = 0.0, []
    for platform, counts in FULL_COUNTS.items():
        for suite, n in counts.items():
            if (platform, suite) in measured:
                total += n * measured[(platform, suite)]
                continue
            if suite == "t3" and (platform, "t2") in measured:  # the same RMFA, on the same platform's videos
                total += n * measured[(platform, "t2")]
                borrowed.append(f"t3_{platform} as t2_{platform}")
                continue
            same = [t for (p, s), t in measured.items() if s == suite] or list(measured.values())
            total += n * float(np.mean(same))
            borrowed.append(f"{suite}_{platform} at other platforms' time")
    return total / workers, borrowed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("pairs", type=Path, nargs="+", metavar="RELEASE SUBMISSION")
    p.add_argument("--limit", type=int, default=12, help="instances per config (default 12)")
    p.add_argument("--workers", type=int, default=2, help="cores assumed for the projection (default 2)")
    args = p.parse_args(argv)
    if len(args.pairs) % 2:
        p.error("give RELEASE SUBMISSION pairs")
    cv2.setNumThreads(1)
    results = [measure(release, submission, c, args.limit)
               for release, submission in zip(args.pairs[::2], args.pairs[1::2]) for c in test_configs(release)]
    print("seconds per instance, every seed of the submission, one core:")
    print("| config | n | seeds | no cache | filling the caches | warm caches | decode floor | warm × floor |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in results:
        print(f"| {r['config']} | {r['n']} | {r['seeds']} | {r['none_s']:.3f} | {r['filling_s']:.3f} | "
              f"{r['warm_s']:.3f} | {r['decode_floor_s']:.3f} | {r['warm_x_floor']:.1f} |")
    total = sum(n for counts in FULL_COUNTS.values() for n in counts.values())
    for mode in MODES:
        seconds, borrowed = project(results, mode, args.workers)
        print(f"projected, {mode} caches: {total} instances on {args.workers} cores: {seconds / 60:.1f} min"
              + (f" ({'; '.join(borrowed)})" if borrowed else ""))
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
