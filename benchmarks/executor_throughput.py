"""Build throughput of the executors: the local process pool against Ray, with 1 and 2 workers (issue: scale-out).

Builds the same small config once per (executor, workers) into fresh folders, checks that every build gives the
same release.json checksums, and prints wall seconds, slots per minute and the ratio to the local executor.

    .venv/bin/python benchmarks/executor_throughput.py --suite t1 --count 8 --tasks PickCube PushCube
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from wsp_data.build import build
from wsp_data.builders import BuildConfig
from wsp_data.schema import RELEASE_JSON


def timed_build(config: BuildConfig, out: Path, executor: str, workers: int) -> tuple[float, dict]:
    start = time.perf_counter()
    result = build(config, out, workers=workers, executor=executor, progress=False)
    seconds = time.perf_counter() - start
    assert result.assembled, f"{executor}×{workers}: not assembled"
    files = json.loads((out / RELEASE_JSON).read_text())["files"]
    return seconds, files


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--suite", default="t1")
    p.add_argument("--platform", default="maniskill")
    p.add_argument("--count", type=int, default=8)
    p.add_argument("--tasks", nargs="+", default=["PickCube", "PushCube"])
    p.add_argument("--runs", nargs="+", default=["local:1", "ray:1", "local:2", "ray:2"],
                   help="executor:workers pairs, in order")
    args = p.parse_args()
    config = BuildConfig(args.suite, args.platform, args.count, tuple(args.tasks))
    rows, reference = [], None
    with tempfile.TemporaryDirectory(prefix="wsp-executors-") as tmp:
        for run in args.runs:
            executor, workers = run.split(":")
            out = Path(tmp) / run.replace(":", "_") / "worldsimprobe"  # same folder name: the card and Croissant name it
            seconds, files = timed_build(config, out, executor, int(workers))
            reference = reference or files
            rows.append((executor, int(workers), seconds, files == reference))
            print(f"{executor}×{workers}: {seconds:.1f} s", flush=True)
    base = {w: s for e, w, s, _ in rows if e == "local"}
    print(f"\n{config.name}, {args.count} slots\n| executor | workers | wall s | slots/min | vs local | same checksums |")
    print("|---|---|---|---|---|---|")
    for executor, workers, seconds, same in rows:
        ratio = f"{base[workers] / seconds:.2f}×" if workers in base else "-"
        print(f"| {executor} | {workers} | {seconds:.1f} | {60 * args.count / seconds:.1f} | {ratio} | {same} |")


if __name__ == "__main__":
    main()
