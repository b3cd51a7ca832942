"""Scoring throughput per suite with the default backends, on one core, against the floor of merely decoding
the same videos; and the projected time of the whole benchmark (paper counts, all three platforms, 3 seeds).

    .venv/bin/python benchmarks/score_speed.py RELEASE SUBMISSION [--workers 2]

SUBMISSION should cover every scored config of RELEASE (e.g. `wsp baseline oracle`). Per instance it times
the reference-side work (`prepare`: decoding the reference and masks, reference flows, the judge on the
reference) and one seed (`score_seed` plus decoding the generated videos), and separately the decode floor
(decoding the generated videos of every seed, plus the reference once for the suites that read it).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval import backends as registry
from wsp_eval.backends import BackendSpec
from wsp_eval.reference import reference_frames
from wsp_eval.release_format import split_config
from wsp_eval.submission import VIDEO_NAME, test_configs
from wsp_eval.suites import SCORERS
from wsp_eval.suites.reference import InstanceReference
from wsp_eval.video import read_video

# instances per suite over the three platforms (SPEC §3: ManiSkill / LIBERO / RoboTwin)
FULL_COUNTS = {"t1": 1000 + 1000 + 419, "t2": 1500 + 1500 + 1575, "t3": 750 + 1000 + 1000,
               "t4": 1000 + 1000 + 640, "t5": 8 * 295 + 4 * 500 + 8 * 233}
SEEDS = 3


def measure(release: Path, submission: Path, config: str, limit: int) -> dict:
    suite, _ = split_config(config)
    module = SCORERS[suite]
    backends = registry.make(BackendSpec(), module.NEEDS)
    rows = pq.read_table(release / config / "instances.parquet").to_pylist()[:limit]
    prep, seed, gen_decode, ref_decode = [], [], [], []
    for row in rows:
        paths = [submission / config / e / VIDEO_NAME.format(seed=0) for e in row["episode_ids"]]
        t = time.perf_counter()
        for p in paths:
            read_video(p)
        gen_decode.append(time.perf_counter() - t)
        t = time.perf_counter()
        for i in row["episode_indices"]:
            reference_frames(release / config, i)
        ref_decode.append(time.perf_counter() - t)
        ref = InstanceReference(release / config, row)
        t = time.perf_counter()
        prepared = module.prepare(ref, backends)
        if hasattr(prepared, "flows"):  # T2/T3 prepare lazily: count the reference flows once, here (no cache)
            prepared.flows(prepared.duration)
        prep.append(time.perf_counter() - t)
        t = time.perf_counter()
        videos = {role: read_video(p) for role, p in zip(row["roles"], paths)}
        module.score_seed(prepared, videos, backends)
        seed.append(time.perf_counter() - t)
    per_instance = np.mean(prep) + SEEDS * np.mean(seed)
    # the floor: decoding the generated videos of every seed, and the reference once where the suite reads it
    per_floor = SEEDS * np.mean(gen_decode) + (np.mean(ref_decode) if suite != "t1" else 0.0)
    return {"config": config, "n": len(rows), "prepare_s": float(np.mean(prep)), "seed_s": float(np.mean(seed)),
            "instance_3seeds_s": float(per_instance), "decode_floor_3seeds_s": float(per_floor),
            "instances_per_s_per_core": float(1 / per_instance), "ratio_to_decode": float(per_instance / per_floor)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("release", type=Path)
    p.add_argument("submission", type=Path)
    p.add_argument("--limit", type=int, default=12, help="instances per config (default 12)")
    p.add_argument("--workers", type=int, default=2, help="cores assumed for the projection (default 2)")
    args = p.parse_args(argv)
    cv2.setNumThreads(1)
    results = [measure(args.release, args.submission, c, args.limit) for c in test_configs(args.release)]
    print("| config | n | prepare s | seed s | instance (3 seeds) s | instances/s/core | × decode floor |")
    print("|---|---|---|---|---|---|---|")
    for r in results:
        print(f"| {r['config']} | {r['n']} | {r['prepare_s']:.3f} | {r['seed_s']:.3f} | {r['instance_3seeds_s']:.3f} "
              f"| {r['instances_per_s_per_core']:.2f} | {r['ratio_to_decode']:.1f} |")
    per_suite = {split_config(r["config"])[0]: r["instance_3seeds_s"] for r in results}
    if "t3" not in per_suite and "t2" in per_suite:
        per_suite["t3"] = per_suite["t2"]  # same RMFA scoring
    total = sum(FULL_COUNTS[s] * per_suite[s] for s in per_suite) / args.workers
    covered = sum(FULL_COUNTS[s] for s in per_suite)
    print(f"\nprojected: {covered} of {sum(FULL_COUNTS.values())} instances × {SEEDS} seeds on {args.workers} cores: "
          f"{total / 3600:.2f} h (suites measured: {', '.join(sorted(per_suite))}; T3 timed as T2 when absent)")
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
