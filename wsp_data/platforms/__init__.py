"""Simulator platforms, found by name in `KITS`; this is the one place that registers the built-in ones, and
other distributions add theirs as `PlatformKit` objects through the entry-point group `worldsimprobe.platforms`
(`wsp_eval.registry`). Simulators are imported only inside the platform packages (`maniskill/`, `libero/`,
`aloha/`), and only when a platform is first used, so building on one platform never imports another's simulator.

A `PlatformKit` (`interface.py`) is everything suite builders need from a platform, hook by hook (tasks, expert,
renderer, the streams the validity checks read, T3 sources, T4 scene edits, T5 primitives), and what the release
stores about it (`info`). docs/guides/adding-a-platform.md describes how to write one.
"""

from __future__ import annotations

from wsp_data.platforms.interface import (
    ARM, BLOCK_RAD, BLOCK_STEPS, NotSupported, Observation, PlatformError, PlatformKit, Rollout, checked_stream,
    joint_blocked,
)
from wsp_eval.registry import Registry

KITS: Registry[PlatformKit] = Registry("platform", "worldsimprobe.platforms")


def kit(platform: str) -> PlatformKit:
    """The kit of `platform` (built-in or from an entry point); KeyError naming the known platforms."""
    return KITS[platform]


def _register_builtin() -> None:
    from wsp_data.platforms.aloha.kit import KIT as ALOHA
    from wsp_data.platforms.libero.kit import KIT as LIBERO
    from wsp_data.platforms.maniskill.kit import KIT as MANISKILL

    KITS.register(MANISKILL.name, MANISKILL)
    KITS.register(LIBERO.name, LIBERO)
    KITS.register(ALOHA.name, ALOHA)


_register_builtin()

__all__ = ["ARM", "BLOCK_RAD", "BLOCK_STEPS", "KITS", "NotSupported", "Observation", "PlatformError", "PlatformKit",
           "Rollout", "checked_stream", "joint_blocked", "kit"]
