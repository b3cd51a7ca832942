"""How the slot phase of a build scales with workers (issue: scale-out, part 4c): the same config's first
`slots-per-worker × W` slots decided by W workers, for each `executor:W` run, into fresh staging folders.

Only slots are decided (no assembly: that is serial and measured by `assembly_speed.py`), so the run needs the
simulator of the platform and, for `ray:W`, Ray, but not LeRobot. Every run decides a prefix of the same build
config, so a slot decided in two runs must be staged identically: the script checks it (a digest of each
slot's record and arrays) and prints, per run, wall seconds, the time to the first decided slot (start-up: worker
processes or Ray, simulators), slots per minute after it, and from that rate the speed-up over the first run with
the fewest workers and the parallel efficiency.

    .venv/bin/python benchmarks/slot_scaling.py --platform aloha --suite t4 --runs ray:1 ray:2 --out scaling.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from wsp_data.build import decide_slots, open_staging
from wsp_data.builders import BuildConfig
from wsp_data.platforms import kit
from wsp_data.staging import SLOT_JSON


def slot_digest(slot_dir: Path) -> str:
    """The staged decision of one slot: its record (less the deciding process's peak memory, which differs between
    runs) and its arrays (not the npz container bytes)."""
    record = json.loads((slot_dir / SLOT_JSON).read_text())
    record.pop("peak_rss_mb", None)
    h = hashlib.sha256(json.dumps(record, sort_keys=True).encode())
    for npz in sorted(slot_dir.glob("*.npz")):
        with np.load(npz) as z:
            for key in sorted(z.files):
                a = z[key]
                h.update(f"{npz.name}:{key}:{a.dtype}:{a.shape}".encode())
                h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def timed_run(config: BuildConfig, root: Path, executor: str, workers: int, slots: int) -> dict:
    staging = open_staging(root, config, restart=True)
    start = time.perf_counter()
    first = None
    kept = attempts = rendered = 0
    for record in decide_slots(config, staging, list(range(slots)), workers, executor):
        first = first or time.perf_counter() - start
        kept += record.kept
        attempts += len(record.attempts)
        rendered += sum(a["rendered_steps"] for a in record.attempts)
    wall = time.perf_counter() - start
    return {"executor": executor, "workers": workers, "slots": slots, "kept": kept, "proposed": attempts,
            "rendered_steps": rendered, "wall_s": round(wall, 2), "first_slot_s": round(first or wall, 2),
            "slots_per_min": round(60 * slots / wall, 2),
            "steady_slots_per_min": round(60 * (slots - 1) / (wall - first), 2) if slots > 1 and first else None,
            "digests": {k: slot_digest(staging.slot_dir(k)) for k in range(slots)}}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--platform", default="aloha")
    p.add_argument("--suite", default="t4")
    p.add_argument("--tasks", nargs="*", default=None)
    p.add_argument("--runs", nargs="+", default=["local:1", "ray:1", "local:2", "ray:2"],
                   help="executor:workers pairs, in order")
    p.add_argument("--slots-per-worker", type=int, default=4)
    p.add_argument("--out", type=Path, default=None, help="JSON with every run and the machine")
    args = p.parse_args()
    runs = [(e, int(w)) for e, w in (r.split(":") for r in args.runs)]
    most = max(w for _, w in runs) * args.slots_per_worker
    config = BuildConfig(args.suite, args.platform, most, tuple(args.tasks or kit(args.platform).tasks()))
    results, digests = [], {}
    with tempfile.TemporaryDirectory(prefix="wsp-scaling-") as tmp:
        for i, (executor, workers) in enumerate(runs):
            r = timed_run(config, Path(tmp) / f"run{i}", executor, workers, workers * args.slots_per_worker)
            mismatched = [k for k, d in r["digests"].items() if digests.setdefault(k, d) != d]
            r["same_as_earlier_runs"] = not mismatched
            results.append(r)
            print(f"{executor}×{workers}: {r['slots']} slots in {r['wall_s']} s (first after {r['first_slot_s']} s), "
                  f"kept {r['kept']}, same decisions as earlier runs: {not mismatched}", flush=True)
    base = min(results, key=lambda r: r["workers"])
    print(f"\n{config.name}: slots decided by W workers ({args.slots_per_worker} per worker), {os.cpu_count()} CPUs\n"
          "| executor | workers | slots | kept | wall s | first slot s | slots/min after it | speed-up | efficiency |"
          "\n|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in results:
        speedup = (r["steady_slots_per_min"] or 0) / (base["steady_slots_per_min"] or float("nan"))
        r["speedup"], r["efficiency"] = round(speedup, 2), round(speedup * base["workers"] / r["workers"], 2)
        print(f"| {r['executor']} | {r['workers']} | {r['slots']} | {r['kept']} | {r['wall_s']} | {r['first_slot_s']} | "
              f"{r['steady_slots_per_min']} | {speedup:.2f}× | {r['efficiency']:.0%} |")
    if args.out:
        machine = {"cpus": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
                   "gl": os.environ.get("MUJOCO_GL")}
        args.out.write_text(json.dumps({"config": config.to_json(), "machine": machine, "runs": results}, indent=1))


if __name__ == "__main__":
    main()
