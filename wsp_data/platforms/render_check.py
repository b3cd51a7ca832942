"""`python -m wsp_data.platforms.render_check`: render one frame of every built-in platform on the CPU (its kit's
`render_check` hook: ManiSkill on SAPIEN, LIBERO on MuJoCo), or fail clearly."""

from __future__ import annotations

import sys

BUILTIN = ("maniskill", "libero")


def main() -> int:
    from wsp_data.platforms import kit
    from wsp_data.platforms.maniskill.runtime import LAVAPIPE_ICD, configure_cpu_rendering

    configure_cpu_rendering()
    if not LAVAPIPE_ICD.exists():
        print(f"render check: {LAVAPIPE_ICD} missing; install mesa-vulkan-drivers 25 (scripts/setup.sh)", file=sys.stderr)
        return 1
    for name in BUILTIN:
        simulator = kit(name).info.simulator
        try:
            frame = kit(name).render_check()
        except Exception as e:  # noqa: BLE001 - report any renderer failure as one clear line
            print(f"render check: {name} ({simulator}) failed to render: {type(e).__name__}: {e}", file=sys.stderr)
            return 1
        if not _good(name, frame):
            return 1
    return 0


def _good(name: str, frame) -> bool:
    if frame.shape != (128, 128, 3) or frame.max() == 0:
        print(f"render check: {name}: bad frame {frame.shape}, max {frame.max()}", file=sys.stderr)
        return False
    print(f"render check: {name} ok, frame {frame.shape}, mean {frame.mean():.1f}")
    return True


if __name__ == "__main__":
    sys.exit(main())
