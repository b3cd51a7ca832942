"""`python -m wsp_data.platforms.render_check`: render one ManiSkill and one LIBERO frame on the CPU, or fail
clearly."""

from __future__ import annotations

import sys


def main() -> int:
    from wsp_data.platforms.maniskill.runtime import LAVAPIPE_ICD, configure_cpu_rendering

    configure_cpu_rendering()
    if not LAVAPIPE_ICD.exists():
        print(f"render check: {LAVAPIPE_ICD} missing; install mesa-vulkan-drivers 25 (scripts/setup.sh)", file=sys.stderr)
        return 1
    try:
        from wsp_data.platforms.maniskill.env import ManiSkillPlatform

        with ManiSkillPlatform("PickCube") as p:
            frame = p.reset(seed=0).rgb
    except Exception as e:  # noqa: BLE001 - report any renderer failure as one clear line
        print(f"render check: SAPIEN failed to render: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    if not _good("SAPIEN", frame):
        return 1
    try:
        from wsp_data.platforms.libero.env import LiberoPlatform
        from wsp_data.platforms.libero.experts import TASKS

        with LiberoPlatform(next(iter(TASKS))) as p:
            frame = p.reset(seed=0).rgb
    except Exception as e:  # noqa: BLE001
        print(f"render check: LIBERO (MuJoCo, MUJOCO_GL=osmesa) failed to render: {type(e).__name__}: {e}",
              file=sys.stderr)
        return 1
    return 0 if _good("MuJoCo", frame) else 1


def _good(name: str, frame) -> bool:
    if frame.shape != (128, 128, 3) or frame.max() == 0:
        print(f"render check: {name}: bad frame {frame.shape}, max {frame.max()}", file=sys.stderr)
        return False
    print(f"render check: {name} ok, frame {frame.shape}, mean {frame.mean():.1f}")
    return True


if __name__ == "__main__":
    sys.exit(main())
