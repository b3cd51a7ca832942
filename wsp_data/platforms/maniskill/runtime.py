"""Process-level settings the CPU renderer needs, applied before SAPIEN is imported."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

LAVAPIPE_ICD = Path("/usr/share/vulkan/icd.d/lvp_icd.json")


def configure_cpu_rendering() -> None:
    """Point Vulkan at Mesa 25's lavapipe, one render thread per worker, a private runtime dir."""
    if LAVAPIPE_ICD.exists():
        os.environ.setdefault("VK_ICD_FILENAMES", str(LAVAPIPE_ICD))
    os.environ.setdefault("LP_NUM_THREADS", "1")
    if "XDG_RUNTIME_DIR" not in os.environ:
        d = Path(tempfile.gettempdir()) / f"wsp-xdg-{os.getuid()}"
        d.mkdir(mode=0o700, exist_ok=True)
        os.environ["XDG_RUNTIME_DIR"] = str(d)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
