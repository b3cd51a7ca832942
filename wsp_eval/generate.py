"""Run a world model over a release and write a submission (spec §4.7.1).

A model is either
- per-episode: any callable `model(first_frame, actions, fps, seed) -> frames`: `first_frame` is the
  reference frame 0 (H, W, 3) uint8, `actions` the episode's action stream float32 (T, D) (column `action`, or
  `action.ee`), `fps` the release's frame rate and `seed` the generation seed; it returns (N, H, W, 3) frames
  (uint8, or numbers in [0, 255]), N = T the episode's reference horizon (one action row per frame: the
  last row repeats the previous action); or
- batched: a callable with an integer attribute `wsp_batch_size` (set it with the `batched(n)` decorator, or
  on a class; namespaced so that a model wrapper's own `batch_size` never switches the call), called as
  `model(requests) -> list of frames`, `requests` a list of at most `wsp_batch_size`
  `Request(first_frame, actions, fps, seed)` of one config (same resolution and action width), answered
  in order.
Both are defined on the model side, `wsp_serve.callables`, which `wsp-serve` runs in a model's own environment
(`wsp_eval.model_client` is the other end: `wsp generate --model ws://HOST:PORT`).
`load_model("module:callable")` finds one, or `load_model(name)` one registered in `MODELS` (a zero-argument
factory, from the entry-point group `worldsimprobe.models`: this distribution declares `reference`, its reference
world model, which needs the `train` extra). A model
may carry a dict `wsp_info` (its version, checkpoints); it is written into submission.json as `model_info`.

`write_submission` is the loop shared with the calibration baselines: each video is written to a temp name
in its folder and renamed into place, so a killed run never leaves a truncated mp4, and the same call run
again skips the videos already there; a batch is checked whole before any of its videos is written.
submission.json is rewritten after every batch; its `generation_seconds` (time spent producing frames: the model
call and reading its inputs) accumulates over resumed runs.
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from tqdm import tqdm

from wsp_eval import folder_lock
from wsp_eval.console import terminal
from wsp_eval.episode import EpisodeContext
from wsp_eval.registry import Registry
from wsp_eval.release_format import BENCHMARK_VERSION, INSTANCES
from wsp_eval.submission import SUBMISSION_JSON, VIDEO_NAME, test_configs
from wsp_eval.video import write_video
from wsp_serve import callables
from wsp_serve.callables import CallableError, load_callable
from wsp_serve.callables import MAX_BATCH, Request, batched  # noqa: F401  (the model side's, re-exported)

Model = Callable[[np.ndarray, np.ndarray, float, int], np.ndarray]
Producer = Callable[[EpisodeContext], np.ndarray]
BatchProducer = Callable[[list[EpisodeContext]], list[np.ndarray]]
Extra = Callable[[dict], dict]  # the previous submission.json (or {}) -> more keys for submission.json


def batch_size_of(model: object) -> int | None:
    """The model's batch size if it is a batched model, None for a per-episode one (GenerateError if invalid)."""
    try:
        return callables.batch_size_of(model)
    except CallableError as e:
        raise GenerateError(str(e)) from None


class GenerateError(RuntimeError):
    """A model, its output, or an output folder that cannot be used; the message names which and where."""


@dataclass(frozen=True)
class GenerateResult:
    written: int  # videos written by this call
    skipped: int  # videos already present (resumed)
    seconds: float  # spent producing frames in this call


MODELS: Registry[Callable[[], Model]] = Registry("model", "worldsimprobe.models")


def load_model(spec: str) -> Model:
    """The model registered in `MODELS` as `spec`, or the callable named by "module:callable" (the attribute may
    be dotted: "module:Class.method"). The current directory is put on the module search path (as `python -m`
    does), so a model file there imports."""
    module_name, sep, attr = spec.partition(":")
    if not sep and spec in MODELS:
        try:
            return MODELS[spec]()
        except ModuleNotFoundError as e:
            raise GenerateError(f"model {spec!r} needs the train extra (missing module {e.name!r}): "
                                "pip install 'worldsimprobe[train]', or `make setup`") from None
    if not (sep and module_name and attr):
        raise GenerateError(f"model {spec!r}: expected 'module:callable', ws://HOST:PORT or a registered name "
                            f"({', '.join(MODELS)})")
    try:
        return load_callable(spec)
    except CallableError as e:
        raise GenerateError(str(e)) from e.__cause__


def generate(model: Model, release: Path, out: Path, *, seeds: Sequence[int] = (0, 1, 2),
             configs: Sequence[str] | None = None, name: str, action_key: str = "action",
             progress: bool = True) -> GenerateResult:
    """Run `model` (per-episode or batched, see the module doc) on every scored episode × seed of `release` (or
    of `configs`) and write, or resume, the submission of model `name` in `out`."""
    size = batch_size_of(model)
    if size is None:
        def produce(ctxs: list[EpisodeContext]) -> list[np.ndarray]:
            return [model(*request_of(ctx, action_key)) for ctx in ctxs]
    else:
        def produce(ctxs: list[EpisodeContext]) -> list[np.ndarray]:
            return model([request_of(ctx, action_key) for ctx in ctxs])  # checked in `_write_batch`

    info = getattr(model, "wsp_info", None)
    return write_submission(produce, release, out, seeds=seeds, configs=configs, name=name, progress=progress,
                            batch_size=size or 1, info=info if isinstance(info, dict) else None)


def request_of(ctx: EpisodeContext, action_key: str) -> Request:
    """What a model is given for episode `ctx`: its first frame and its `action_key` stream (writable copies)."""
    try:
        actions = ctx.actions(action_key)
    except ValueError as e:
        raise GenerateError(str(e)) from None
    return Request(ctx.first_frame().copy(), actions.copy(), ctx.fps, ctx.seed)


def write_submission(produce: BatchProducer, release: Path, out: Path, *, seeds: Sequence[int],
                     configs: Sequence[str] | None = None, name: str, progress: bool, batch_size: int = 1,
                     info: dict | None = None, extra: Extra | None = None) -> GenerateResult:
    """Write `produce(contexts)` (a list of frames per list of up to `batch_size` episode contexts) for every
    scored episode × seed as `<out>/<config>/<episode_id>/seed<k>.mp4`, skipping videos already there, then
    submission.json; `out` is held by this process alone (`wsp_eval.folder_lock`). `extra(previous)`, given the
    submission.json found in `out` ({} if none), returns more keys for it: it is called before the first video
    (a GenerateError there refuses the folder) and at every rewrite."""
    release, out = Path(release), Path(out)
    seeds, configs = _check_seeds(seeds), _check_configs(release, configs)
    if not isinstance(name, str) or not name:
        raise GenerateError(f"model name must be a non-empty string, got {name!r}")
    try:
        with folder_lock.exclusive(out, "wsp generate"):
            return _write_locked(produce, release, out, seeds, configs, name, progress, batch_size, info, extra)
    except folder_lock.FolderBusy as e:
        raise GenerateError(str(e)) from None


def _write_locked(produce: BatchProducer, release: Path, out: Path, seeds: list[int], configs: list[str],
                  name: str, progress: bool, batch_size: int, info: dict | None,
                  extra: Extra | None) -> GenerateResult:
    previous = _previous_manifest(out, name)
    before = previous.get("generation_seconds", 0)
    before = float(before) if isinstance(before, (int, float)) and not isinstance(before, bool) else 0.0
    more = (lambda: extra(previous)) if extra else dict
    more()
    written = skipped = 0
    seconds = 0.0
    total = len(seeds) * sum(len(ids) for c in configs for ids in _column(release, c, "episode_ids"))
    pending: list[tuple[EpisodeContext, Path]] = []

    def flush() -> None:
        nonlocal written, seconds
        if pending:
            seconds += _write_batch(produce, pending)
            written += len(pending)
            _write_manifest(out, name, seeds, configs, before + seconds, info, more())
            bar.update(len(pending))
            pending.clear()

    with tqdm(total=total, desc=name, unit="video", disable=not progress, file=terminal()) as bar:
        for ctx in episode_contexts(release, configs, seeds[0]):
            for seed in seeds:
                path = out / ctx.config / ctx.episode_id / VIDEO_NAME.format(seed=seed)
                if path.exists():
                    skipped += 1
                    bar.update()
                    continue
                if pending and pending[0][0].config != ctx.config:
                    flush()  # a batch never mixes configs: one platform, one resolution, one action width
                pending.append((replace(ctx, seed=seed), path))
                if len(pending) >= batch_size:
                    flush()
        flush()
    _write_manifest(out, name, seeds, configs, before + seconds, info, more())
    return GenerateResult(written, skipped, seconds)


def per_episode(produce: Producer) -> BatchProducer:
    """A batch producer calling the per-episode `produce` once per context."""
    return lambda ctxs: [produce(ctx) for ctx in ctxs]


def check_frames(frames: object, num_frames: int, where: str, size: tuple[int, int] | None = None) -> np.ndarray:
    """`frames` as (num_frames, H, W, 3) uint8 — (H, W) = `size` when given, the reference's — or a GenerateError
    naming `where` and what is wrong (`wsp_serve.callables.check_frames`, which a model server runs too)."""
    try:
        return callables.check_frames(frames, num_frames, where, size)
    except CallableError as e:
        raise GenerateError(str(e)) from None


def _write_batch(produce: BatchProducer, items: list[tuple[EpisodeContext, Path]]) -> float:
    """Produce, check and atomically write a batch of videos; returns the seconds spent producing them."""
    where = ", ".join(f"{ctx.config}/{ctx.episode_id}/seed{ctx.seed}" for ctx, _ in items[:3])
    where += f" (+{len(items) - 3} more)" if len(items) > 3 else ""
    start = time.perf_counter()
    try:
        batch = produce([ctx for ctx, _ in items])
    except Exception as e:
        e.add_note(f"while generating {where}")
        raise
    seconds = time.perf_counter() - start
    if not isinstance(batch, (list, tuple)) or len(batch) != len(items):
        got = f"{len(batch)} item(s)" if isinstance(batch, (list, tuple)) else f"a {type(batch).__name__}"
        raise GenerateError(f"{where}: asked for {len(items)} video(s), returned {got}; a batched model returns a "
                            "list with one frame array per request, in order")
    checked = [check_frames(frames, ctx.num_frames, f"{ctx.config}/{ctx.episode_id}/seed{ctx.seed}",
                            ctx.first_frame().shape[:2]) for frames, (ctx, _) in zip(batch, items)]
    for frames, (ctx, path) in zip(checked, items):
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.partial{path.suffix}")  # keeps .mp4: the muxer goes by the suffix
        try:
            write_video(tmp, frames, ctx.fps)
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
    return seconds


def episode_contexts(release: Path, configs: Sequence[str], seed: int = 0) -> Iterator[EpisodeContext]:
    """One context per scored episode of `configs` (per role of each instance row, in table order), lazily (each
    holds its decoded frames until dropped)."""
    for config in configs:
        for row in pq.read_table(release / config / INSTANCES).to_pylist():
            for role, index in zip(row["roles"], row["episode_indices"]):
                yield EpisodeContext(release, config, row, role, int(index), float(row["fps"]), seed)


def _column(release: Path, config: str, column: str) -> list:
    return pq.read_table(release / config / INSTANCES, columns=[column]).column(column).to_pylist()


def _check_seeds(seeds: Sequence[int]) -> list[int]:
    seeds = list(seeds)
    if not seeds or len(set(seeds)) != len(seeds) or not all(
            isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
        raise GenerateError(f"seeds must be distinct non-negative integers, got {seeds}")
    return seeds


def _check_configs(release: Path, configs: Sequence[str] | None) -> list[str]:
    known = test_configs(release)
    if configs is None:
        return known
    unknown = [c for c in configs if c not in known]
    if unknown or not configs:
        raise GenerateError(f"{release}: configs {list(configs)} not among its scored configs ({', '.join(known)})")
    return list(configs)


def _previous_manifest(out: Path, name: str) -> dict:
    """The submission.json of the same model already in `out` ({} if none); refuses another model's."""
    path = out / SUBMISSION_JSON
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise GenerateError(f"{path}: not valid JSON ({e}); remove it or write to another folder") from None
    model = meta.get("model") if isinstance(meta, dict) else None
    if model != name:
        raise GenerateError(f"{path}: holds a submission of model {model!r}, not {name!r}; write to another folder")
    return meta


def _write_manifest(out: Path, name: str, seeds: list[int], configs: list[str], seconds: float,
                    info: dict | None = None, extra: dict | None = None) -> None:
    meta = {"model": name, "benchmark_version": BENCHMARK_VERSION, "seeds": seeds, "configs": configs,
            "hardware": platform.processor() or platform.machine(), "generation_seconds": round(seconds, 3)}
    if info:
        meta["model_info"] = info
    meta.update(extra or {})
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / f".{SUBMISSION_JSON}.partial"
    tmp.write_text(json.dumps(meta, indent=1))
    os.replace(tmp, out / SUBMISSION_JSON)
