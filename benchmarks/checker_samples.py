"""The T5 label judge's reference check, drawn many times: tiny T5 builds of 8 references on scenes that no judge
was trained, tuned or measured on (`--seed-range private`, one build seed per sample, `wsp build --seed`),
and the oracle's "primitive recognised" column on each, which is the judge's agreement averaged within primitive,
then across primitives, as `wsp score` reports it beside T5. A sample passes at ≥ 90 (a sample of 8: every
reference right).

    .venv/bin/python benchmarks/checker_samples.py --platform maniskill --seeds 101 102 103 --out DIR [--workers 2]

Builds go to DIR/<platform>-<seed> (an existing one is reused); prints one row per sample with its misses, then
the pass count and the references' agreement.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np

from wsp_eval.backends import BackendSpec, make
from wsp_eval.backends.judge import score_verdict
from wsp_eval.judge_data import t5_clips
from wsp_eval.release_format import ReleaseError, load_release

PASS = 90.0


def build(platform: str, seed: int, out: Path, count: int, workers: int) -> Path:
    """The sample's release (built unless `out` already holds its T5 config)."""
    config = f"t5_{platform}"
    try:
        if config in load_release(out)["configs"]:
            return out
    except ReleaseError:
        pass
    cmd = [sys.executable, "-m", "wsp_eval.cli", "build", "--platform", platform, "--suite", "t5", "--count",
           str(count), "--seed-range", "private", "--seed", str(seed), "--workers", str(workers), "--quiet",
           "--out", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        sys.exit(f"checker_samples: building {out} failed:\n{done.stderr.strip()}")
    return out


def judge_sample(release: Path, platform: str, judge) -> tuple[float, list[dict]]:
    """The oracle's "primitive recognised" on one sample (the judge's score per reference, averaged within primitive, then across) and every
    reference's verdict."""
    verdicts = []
    for clip in t5_clips(release, f"t5_{platform}", ("reference",)):
        v = judge.judge(clip.judge_frames(), clip.object_px, platform)
        score = score_verdict(v, clip.primitive)
        verdicts.append({"task": clip.task, "primitive": clip.primitive, "label": v.label, "agent_ok": v.agent_ok,
                         "object_ok": v.object_ok, "full": score == 100.0, "score": score})
    per: dict[str, list[float]] = defaultdict(list)
    for v in verdicts:
        per[v["primitive"]].append(v["score"])
    return float(np.mean([np.mean(x) for x in per.values()])), verdicts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platform", required=True, choices=("maniskill", "libero", "aloha"))
    ap.add_argument("--seeds", type=int, nargs="+", required=True, help="build seeds, one sample each (not 0)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--count", type=int, default=8)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    if 0 in args.seeds:
        ap.error("build seed 0 cannot key the private range")
    cv2.setNumThreads(1)
    judge = make(BackendSpec(judge="net"), ("judge",)).judge
    print(f"judge net {judge.version}, {args.platform}, samples of {args.count}\n")
    print("| build seed | oracle's T5 | misses (task: intended → label, agent_ok, object_ok) |\n|---:|---:|---|")
    scores, agree, total = [], 0, 0
    for seed in args.seeds:
        release = build(args.platform, seed, args.out / f"{args.platform}-{seed}", args.count, args.workers)
        score, verdicts = judge_sample(release, args.platform, judge)
        scores.append(score)
        agree += sum(v["full"] for v in verdicts)
        total += len(verdicts)
        misses = "; ".join(f"{v['task']}: {v['primitive']} → {v['label']}, {v['agent_ok']}, {v['object_ok']}"
                           for v in verdicts if not v["full"])
        print(f"| {seed} | {score:.1f} | {misses or '–'} |", flush=True)
    passed = sum(s >= PASS for s in scores)
    print(f"\n{passed} of {len(scores)} samples pass (≥ {PASS:.0f}); references scoring 100: {agree} of {total} "
          f"({100 * agree / max(total, 1):.1f} %)")


if __name__ == "__main__":
    main()
