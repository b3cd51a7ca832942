"""Process-level set-up ALOHA needs before MuJoCo is imported: a CPU OpenGL backend, and the MJCF / STL asset
folder of the installed gym-aloha 0.1.5 wheel.

The wheel is installed without its dependencies and never imported (its `__init__` pulls gymnasium and
dm_control): only its `assets/` folder is read, located through the import system without executing it.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

SCENE_XML = "bimanual_viperx_transfer_cube.xml"  # the joint-position scene every task is built on


class AlohaUnavailable(ImportError):
    """gym-aloha's assets are not installed."""


def aloha_assets() -> Path:
    """gym-aloha's `assets/` folder (MJCF scenes and meshes), without importing the package."""
    spec = importlib.util.find_spec("gym_aloha")
    if spec is None or not spec.submodule_search_locations:
        raise AlohaUnavailable("the ALOHA platform needs the package 'gym_aloha' (gym-aloha 0.1.5, its assets only); "
                               "run `make setup` (scripts/setup.sh installs it with --no-deps)")
    assets = Path(list(spec.submodule_search_locations)[0]) / "assets"
    if not (assets / SCENE_XML).is_file():
        raise AlohaUnavailable(f"{assets}: {SCENE_XML} missing; reinstall gym-aloha 0.1.5 (`make setup`)")
    return assets


def configure_aloha() -> Path:
    """Select a CPU GL backend (unless one is set) and return the asset folder. Call before importing mujoco."""
    os.environ.setdefault("MUJOCO_GL", "osmesa")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    return aloha_assets()


def offscreen_renderer() -> type:
    """`mujoco.Renderer`, also when mujoco was imported before `configure_aloha` chose a GL backend (another
    platform's simulator imported it first in this process, with MUJOCO_GL unset): mujoco then fell back to GLFW,
    failed without a display and left `Renderer` out; its renderer module is imported again with the CPU backend."""
    import importlib

    import mujoco

    if not hasattr(mujoco, "Renderer"):
        configure_aloha()
        mujoco.Renderer = importlib.import_module("mujoco.rendering.classic.renderer").Renderer
    return mujoco.Renderer
