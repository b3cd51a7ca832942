"""The two model callables `wsp generate` runs, in process or behind `wsp-serve`.

- per-episode: `model(first_frame, actions, fps, seed) -> frames`: `first_frame` (H, W, 3) uint8, `actions`
  float32 (T, D), one row per frame; it returns (T, H, W, 3) frames, uint8 or numbers in [0, 255];
- batched: a callable with an integer attribute `wsp_batch_size` (the `batched(n)` decorator sets it), called as
  `model(requests) -> list of frames` with at most `wsp_batch_size` `Request`s of one config, answered in order.

A model may carry a dict `wsp_info` (its version, checkpoints). Nothing here imports WorldSimProbe.
"""

from __future__ import annotations

import functools
import importlib
import os
import sys
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

MAX_BATCH = 1024


class Request(NamedTuple):
    """One video a batched model is asked for (the per-episode call's arguments)."""
    first_frame: np.ndarray  # (H, W, 3) uint8, the reference frame 0
    actions: np.ndarray  # (T, D) float32
    fps: float
    seed: int


class CallableError(ValueError):
    """A model callable, or its output, that cannot be used; the message names which and what is wrong."""


def batched(batch_size: int) -> Callable[[Callable], Callable]:
    """Mark `fn(requests: list[Request]) -> list[frames]` as a batched model taking up to `batch_size` requests."""
    def mark(fn: Callable) -> Callable:
        fn.wsp_batch_size = batch_size
        return fn
    return mark


def batch_size_of(model: object) -> int | None:
    """The model's batch size if it is a batched model, None for a per-episode one (CallableError if invalid)."""
    size = getattr(model, "wsp_batch_size", None)
    if size is None:
        return None
    if isinstance(size, bool) or not isinstance(size, int) or not 1 <= size <= MAX_BATCH:
        raise CallableError(f"model wsp_batch_size {size!r}: expected an integer from 1 to {MAX_BATCH}")
    return size


def load_callable(spec: str) -> Callable:
    """The callable named by "module:callable" (the attribute may be dotted: "module:Class.method"). The current
    directory is put on the module search path (as `python -m` does), so a model file there imports."""
    module_name, sep, attr = spec.partition(":")
    if not (sep and module_name and attr):
        raise CallableError(f"model {spec!r}: expected 'module:callable'")
    if os.getcwd() not in sys.path and "" not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ImportError as e:
        raise CallableError(f"model {spec!r}: cannot import module {module_name!r} ({e})") from e
    try:
        obj = functools.reduce(getattr, attr.split("."), module)
    except AttributeError:
        raise CallableError(f"model {spec!r}: module {module_name!r} has no attribute {attr!r}") from None
    if not callable(obj):
        raise CallableError(f"model {spec!r}: {attr!r} is a {type(obj).__name__}, not callable")
    return obj


def run_batch(model: Callable, requests: list[Request]) -> list:
    """`model`'s answer to `requests`: one call of a batched model, one call per request of a per-episode one."""
    if batch_size_of(model) is None:
        return [model(*r) for r in requests]
    return model(requests)


def check_frames(frames: object, num_frames: int, where: str, size: tuple[int, int] | None = None, *,
                 of: str = "the reference") -> np.ndarray:
    """`frames` as (num_frames, H, W, 3) uint8 — (H, W) = `size` when given — or a CallableError naming `where`
    and what is wrong (`of` names what the count and size come from). Numbers in [0, 255] are rounded."""
    try:
        arr = np.asarray(frames)
    except (TypeError, ValueError, RuntimeError) as e:
        raise CallableError(f"{where}: the model returned a {type(frames).__name__}, not an array ({e})") from None
    if arr.dtype.kind not in "uif":
        raise CallableError(f"{where}: frames of dtype {arr.dtype}; expected uint8 (or numbers in [0, 255])")
    if arr.ndim != 4 or arr.shape[-1] != 3 or 0 in arr.shape[1:3]:
        raise CallableError(f"{where}: frames of shape {arr.shape}; expected (N, H, W, 3)")
    if len(arr) != num_frames:
        raise CallableError(f"{where}: {len(arr)} frames; {of} horizon is {num_frames}")
    if size is not None and arr.shape[1:3] != tuple(size):
        raise CallableError(f"{where}: frames of {arr.shape[2]}×{arr.shape[1]} pixels; {of} frame is "
                            f"{size[1]}×{size[0]}: return frames at its resolution (resample in the model's "
                            "adapter, or declare the model's own size with `wsp-serve --resolution WxH`; scoring "
                            "refuses other resolutions, docs/submission.md)")
    if arr.dtype == np.uint8:
        return arr
    if not np.isfinite(arr).all():
        raise CallableError(f"{where}: frames contain NaN or infinite values")
    lo, hi = arr.min(), arr.max()
    if lo < 0 or hi > 255:
        raise CallableError(f"{where}: values span [{lo}, {hi}], outside [0, 255]")
    return np.rint(arr).astype(np.uint8)
