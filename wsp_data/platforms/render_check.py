"""`python -m wsp_data.platforms.render_check`: render one ManiSkill frame on the CPU or fail clearly."""

from __future__ import annotations

import sys


def main() -> int:
    from wsp_data.platforms.runtime import LAVAPIPE_ICD, configure_cpu_rendering

    configure_cpu_rendering()
    if not LAVAPIPE_ICD.exists():
        print(f"render check: {LAVAPIPE_ICD} missing; install mesa-vulkan-drivers 25 (scripts/setup.sh)", file=sys.stderr)
        return 1
    try:
        from wsp_data.platforms.maniskill import ManiSkillPlatform

        with ManiSkillPlatform("PickCube") as p:
            frame = p.reset(seed=0).rgb
    except Exception as e:  # noqa: BLE001 - report any renderer failure as one clear line
        print(f"render check: SAPIEN failed to render: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    if frame.shape != (128, 128, 3) or frame.max() == 0:
        print(f"render check: bad frame {frame.shape}, max {frame.max()}", file=sys.stderr)
        return 1
    print(f"render check: ok, frame {frame.shape}, mean {frame.mean():.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
