"""What a kept instance costs the builder against the bare simulator, per stage.

For each ManiSkill task, `--seeds` training-range instances of the train suite (one scripted-expert episode
each) are decided in this one process, timing each stage of `TrainBuilder.attempt` and of staging in CPU
seconds of this process (`time.process_time`: robust to other work on the machine):

- script: the expert's scripted episode (end-effector control, unrendered), which makes the action stream;
- render: the rendered replay — the "bare simulator" cost: reset, step and render, with the observations read;
- checks: the spec §5 validity checks; stage: the rollout encoded as it is staged (its video, label PNGs and
  arrays);
- verify (not part of the total): the expert's unrendered verifying replay, which the train builder skips (the
  rendered replay checks success itself); the other suites run it first.

Prints per task and in total the CPU seconds per stage and the ratio of the whole to the rendered replay, and
the wall time per rendered step. Run two copies at once to see what two busy cores cost each other.

    .venv/bin/python benchmarks/builder_overhead.py --tasks PickCube PushCube StackCube --seeds 4
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

from wsp_data.builders.rig import TaskRig
from wsp_data.platforms import kit
from wsp_data.platforms.maniskill.skills import verify
from wsp_data.schema import scene_seed
from wsp_data.staging import RolloutArrays

STAGES = ("script", "render", "checks", "stage")  # what the train builder does per instance


def instance(rig: TaskRig, seed: int) -> tuple[dict[str, float], int] | None:
    """CPU seconds per stage of one kept train instance, and its rendered steps (None: not kept)."""
    cpu: dict[str, float] = {}
    start, t = time.perf_counter(), time.process_time()
    actions = rig.expert.scripted(seed)
    cpu["script"], t = time.process_time() - t, time.process_time()
    ro = rig.render.replay(seed, actions)
    cpu["render"], t = time.process_time() - t, time.process_time()
    problem = rig.invalid(ro)
    cpu["checks"], t = time.process_time() - t, time.process_time()
    RolloutArrays.from_rollout("expert", ro).encode(kit("maniskill").info.fps)
    cpu["stage"] = time.process_time() - t
    cpu["wall"], t = time.perf_counter() - start, time.process_time()
    verify(rig.expert.replayer, seed, actions)
    cpu["verify"] = time.process_time() - t
    return (cpu, len(actions)) if ro.success and problem is None else None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tasks", nargs="+", default=["PickCube", "PushCube", "StackCube"])
    p.add_argument("--seeds", type=int, default=4)
    args = p.parse_args()
    total, total_steps = defaultdict(float), 0
    print("| task | kept | rendered steps | " + " | ".join(f"{s} s" for s in STAGES) + " | all / render | verify s |")
    print("|---|---:|---:|" + "---:|" * (len(STAGES) + 2))
    for task in args.tasks:
        rig = TaskRig(task, "maniskill")
        try:
            instance(rig, scene_seed("train", 0, 0))  # warm-up: first reset and render of the process
            per, steps, kept = defaultdict(float), 0, 0
            for k in range(args.seeds):
                out = instance(rig, scene_seed("train", k + 1, 0))
                if out is None:
                    continue
                cpu, n = out
                kept, steps = kept + 1, steps + n
                for s in (*STAGES, "wall", "verify"):
                    per[s] += cpu[s]
        finally:
            rig.close()
        for s in (*STAGES, "wall", "verify"):
            total[s] += per[s]
        total_steps += steps
        print(f"| {task} | {kept} | {steps} | " + " | ".join(f"{per[s]:.2f}" for s in STAGES)
              + f" | {sum(per[s] for s in STAGES) / per['render']:.2f}× | {per['verify']:.2f} |")
    cpu = sum(total[s] for s in STAGES)
    print(f"| all | | {total_steps} | " + " | ".join(f"{total[s]:.2f}" for s in STAGES)
          + f" | {cpu / total['render']:.2f}× | {total['verify']:.2f} |")
    print(f"\nper rendered step: render {1000 * total['render'] / total_steps:.1f} ms of CPU, everything "
          f"{1000 * cpu / total_steps:.1f} ms of CPU and {1000 * total['wall'] / total_steps:.1f} ms of wall")


if __name__ == "__main__":
    main()
