"""Measure the cost of a rollout on this machine: scripted expert (state-only), unrendered replay, rendered
replay, and the LeRobot write of one episode. Prints seconds and ratios; asserts nothing.

    .venv/bin/python benchmarks/rollout_speed.py [--tasks PickCube PushCube] [--seeds 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from wsp_data.platforms.maniskill.env import ManiSkillPlatform
from wsp_data.platforms.maniskill.experts import TASKS, ExpertSource
from wsp_data.platforms import kit
from wsp_data.staging import RolloutArrays, SlotRecord, StagedRollout
from wsp_data.writer import write_config


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", nargs="+", default=list(TASKS))
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    print(f"{'task':<16} {'steps':>5} {'script s':>9} {'state s':>8} {'render s':>9} {'ms/step':>8} {'render/state':>12}")
    totals = np.zeros(4)
    sample: RolloutArrays | None = None
    for task in args.tasks:
        es = ExpertSource(task)
        t0 = time.perf_counter()
        render = ManiSkillPlatform(task, render=True, objects=es.spec.objects)
        first_env = time.perf_counter() - t0
        rows = []
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            actions = es.trajectory(seed)
            t_script = time.perf_counter() - t0
            if actions is None:
                continue
            t0 = time.perf_counter()
            es.replayer.replay(seed, actions)
            t_state = time.perf_counter() - t0
            t0 = time.perf_counter()
            ro = render.replay(seed, actions)
            t_render = time.perf_counter() - t0
            rows.append((len(actions), t_script, t_state, t_render))
            sample = sample or RolloutArrays.from_rollout("original", ro)
        es.close()
        render.close()
        if not rows:
            print(f"{task:<16} no successful seed")
            continue
        steps, sc, st, rd = np.mean(rows, axis=0)
        totals += [steps, sc, st, rd]
        print(f"{task:<16} {steps:5.0f} {sc:9.2f} {st:8.2f} {rd:9.2f} {rd / steps * 1000:8.1f} {rd / st:12.1f}"
              f"   (env creation {first_env:.1f} s)")
    steps, sc, st, rd = totals / len(args.tasks)
    print(f"\nmean rendered rollout: {rd:.2f} s for {steps:.0f} steps ({rd / steps * 1000:.1f} ms/step); "
          f"unrendered replay {st:.2f} s (rendering costs {rd / st:.0f}× the physics)")
    if sample is not None:
        fps = kit("maniskill").info.fps
        sample.encode(fps)  # the first call imports the encoder's libraries
        t0 = time.perf_counter()
        staged = StagedRollout.decode(sample.encode(fps))
        encode = time.perf_counter() - t0
        with tempfile.TemporaryDirectory() as d:
            rec = SlotRecord(0, row={"instance_id": "bench/0", "suite": "t1", "task": "bench", "source": "bench",
                                     "instruction": "bench", "objects": []}, roles=["original"])
            t0 = time.perf_counter()
            write_config(Path(d) / "bench", "bench", "maniskill", [(rec, [staged])] * 4)
            per = (time.perf_counter() - t0) / 4
        print(f"staging (h264 crf 0 + PNG masks, in the build worker): {encode:.2f} s per {staged.num_frames}-frame "
              f"episode ({encode / rd:.2f}× a rendered rollout); LeRobot write (parquet, metadata): {per:.2f} s "
              f"({per / rd:.2f}×)")


if __name__ == "__main__":
    main()
