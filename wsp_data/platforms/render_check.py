"""`python -m wsp_data.platforms.render_check [PLATFORM ...]`: render one frame of every registered platform (or of
those named) that has a render check (its kit's `render_check` hook: ManiSkill on SAPIEN, LIBERO on MuJoCo, …)
on the CPU, or fail clearly."""

from __future__ import annotations

import sys

import numpy as np


def main(names: list[str] | None = None) -> int:
    from wsp_data.platforms import KITS, NotSupported, PlatformKit

    checked = 0
    for name in names or list(KITS):
        k = KITS[name]
        if type(k).render_check is PlatformKit.render_check:
            continue  # the platform declares no render check
        try:
            frame = k.render_check()
        except NotSupported:
            continue
        except Exception as e:  # noqa: BLE001 - report any renderer failure as one clear line
            print(f"render check: {name} ({k.info.simulator}) failed to render: {type(e).__name__}: {e}",
                  file=sys.stderr)
            return 1
        if not _good(name, frame, (k.info.height, k.info.width, 3)):
            return 1
        checked += 1
    if not checked:
        print("render check: no registered platform has a render check", file=sys.stderr)
        return 1
    return 0


def _good(name: str, frame: np.ndarray, shape: tuple[int, ...]) -> bool:
    frame = np.asarray(frame)
    if frame.shape != shape or frame.dtype != np.uint8 or frame.max() == 0:
        print(f"render check: {name}: bad frame {frame.shape} {frame.dtype}, max {frame.max()} (expected {shape} "
              "uint8, not black)", file=sys.stderr)
        return False
    print(f"render check: {name} ok, frame {frame.shape}, mean {frame.mean():.1f}")
    return True


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
