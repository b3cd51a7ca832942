"""The submission contract (spec §4.7.1) and its validate-only check.

    <submission>/submission.json            model, benchmark_version, seeds [, configs, hardware, generation_seconds, model_info]
    <submission>/<config>/<episode_id>/seed<k>.mp4

`validate` lists every problem at once, each naming the file: missing or extra files, unreadable or
truncated videos, lossy or chroma-subsampled encodings (`wsp_eval.video.encoding_problem`), zero frames, a frame count other than the reference horizon, a side over `MAX_SIDE`,
a resolution other than the reference's (`RESAMPLED`), videos of one instance at different resolutions, constant videos, fps missing or absurd, links (a
submission holds plain files only; a link pointing outside it is named as such), a submission.json over
`MAX_MANIFEST_BYTES` or malformed, and a benchmark version that does not match the release. It never raises
on bad input, and decoding is bounded (`wsp_eval.video.read_video`): one video at a time, refused from its
header or stopped at the first frame past the horizon, so memory stays bounded whatever is uploaded.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from wsp_eval.folder_lock import LOCK_NAME
from wsp_eval.integrity import check as check_release, repair
from wsp_eval.reference import reference_size
from wsp_eval.release_format import INSTANCES, RELEASE_JSON
from wsp_eval.video import MAX_FPS, MIN_FPS, VideoError, read_video

SUBMISSION_JSON = "submission.json"
VIDEO_NAME = "seed{seed}.mp4"
REQUIRED_KEYS = {"model": str, "benchmark_version": str, "seeds": list}
TRAIN_PREFIX = "train_"
MAX_MANIFEST_BYTES = 1 << 20  # submission.json holds a few short fields; a larger one is refused unread
RESAMPLED = ("export at the reference's resolution (a resampled oracle loses up to 5 points of T1-T3, "
             "docs/submission.md), or score it anyway with `wsp score --accept-lossy`")


@dataclass(frozen=True)
class Problem:
    path: str  # relative to the submission folder (a release file: its full path)
    message: str
    fatal: bool = False  # nothing can be scored (a link in the submission, a config missing from the release)

    def __str__(self) -> str:
        return f"{self.path}: {self.message}"


@dataclass(frozen=True)
class Expected:
    """One video the submission must hold."""

    config: str
    episode_id: str
    seed: int
    num_frames: int
    fps: float
    instance_id: str = ""
    size: tuple[int, int] | None = None  # (H, W) of the reference video; None: not checked

    @property
    def relpath(self) -> str:
        return f"{self.config}/{self.episode_id}/{VIDEO_NAME.format(seed=self.seed)}"


def test_configs(release: Path) -> list[str]:
    """The scored configs of a release (training splits excluded)."""
    rel = json.loads((Path(release) / RELEASE_JSON).read_text())
    return sorted(c for c in rel["configs"] if not c.startswith(TRAIN_PREFIX))


def expected_videos(release: Path, configs: list[str], seeds: list[int]) -> list[Expected]:
    out = []
    for config in configs:
        columns = ["instance_id", "episode_ids", "num_frames", "fps"]
        table = pq.read_table(Path(release) / config / INSTANCES, columns=columns)
        size = reference_size(Path(release) / config)
        for instance, ids, frames, fps in zip(*(table.column(c).to_pylist() for c in columns)):
            for episode_id, n in zip(ids, frames):
                out.extend(Expected(config, episode_id, s, n, fps, instance, size) for s in seeds)
    return out


def _read_manifest(sub: Path, release_version: str, release_configs: list[str]) -> tuple[dict | None, list[Problem]]:
    path = sub / SUBMISSION_JSON
    if not path.is_file():
        return None, [Problem(SUBMISSION_JSON, "missing")]
    if path.stat().st_size > MAX_MANIFEST_BYTES:
        return None, [Problem(SUBMISSION_JSON, f"{path.stat().st_size / 1e6:.1f} MB; at most "
                                               f"{MAX_MANIFEST_BYTES // 1024} KiB is read (it holds model, "
                                               "benchmark_version, seeds and a few optional fields)")]
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        return None, [Problem(SUBMISSION_JSON, f"not valid JSON ({e})")]
    except RecursionError:
        return None, [Problem(SUBMISSION_JSON, "not valid JSON (nested too deep)")]
    if not isinstance(meta, dict):
        return None, [Problem(SUBMISSION_JSON, "must be a JSON object")]
    problems = [Problem(SUBMISSION_JSON, f"'{k}' missing or not a {t.__name__}")
                for k, t in REQUIRED_KEYS.items() if not isinstance(meta.get(k), t)]
    seeds = meta.get("seeds")
    if isinstance(seeds, list) and (not seeds or not all(type(s) is int and s >= 0 for s in seeds)
                                    or len(set(seeds)) != len(seeds)):
        problems.append(Problem(SUBMISSION_JSON, "'seeds' must be a non-empty list of distinct non-negative integers"))
    version = meta.get("benchmark_version")
    if isinstance(version, str) and version != release_version:
        problems.append(Problem(SUBMISSION_JSON, f"benchmark_version {version!r} does not match the release "
                                                 f"({release_version!r})"))
    configs = meta.get("configs", release_configs)
    if not isinstance(configs, list) or not configs:
        problems.append(Problem(SUBMISSION_JSON, "'configs' must be a non-empty list when given"))
    else:
        unknown = [c for c in configs if c not in release_configs]
        if unknown:
            problems.append(Problem(SUBMISSION_JSON, f"configs not in the release: {', '.join(map(str, unknown))}"))
    return (meta if not problems else None), problems


def _shown(path: Path, sub: Path) -> str:
    """`path` relative to the submission, printable whatever bytes its name holds (undecodable ones as \\xNN)."""
    return str(path.relative_to(sub)).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def _links(sub: Path) -> list[Problem]:
    problems = []
    root = sub.resolve()
    for p in sorted(sub.rglob("*")):
        if p.is_symlink():
            target = p.resolve()
            where = "outside the submission" if root not in target.parents and target != root else "inside it"
            problems.append(Problem(_shown(p, sub), f"is a link ({where}: {target}); submit plain files", fatal=True))
    return problems


def load_video(path: Path, exp: Expected, rel: str, *, accept_lossy: bool = False
               ) -> tuple[tuple[np.ndarray, float] | None, list[Problem]]:
    """Decode a submitted video once, bounded by the reference horizon and `MAX_SIDE` (`read_video`) and, unless
    `accept_lossy`, refused when its encoding is lossy (`wsp_eval.video.encoding_problem`) or its resolution is
    not the reference's (`exp.size`): (frames, fps) when it meets the contract, and its problems."""
    if path.stat().st_size == 0:
        return None, [Problem(rel, "empty file (zero frames)")]
    try:
        frames, fps = read_video(path, max_frames=exp.num_frames, lossless=not accept_lossy)
    except VideoError as e:
        return None, [Problem(rel, str(e).removeprefix(f"{path}: "))]
    problems = check_frames(frames, fps, exp, rel)
    if not accept_lossy and exp.size and len(frames) and frames.shape[1:3] != tuple(exp.size):
        (h, w), (rh, rw) = frames.shape[1:3], exp.size
        problems.append(Problem(rel, f"{w}×{h} pixels; the references of {exp.config} are {rw}×{rh}: {RESAMPLED}"))
    return (None if problems else (frames, fps)), problems


def check_frames(frames: np.ndarray, fps: float, exp: Expected, rel: str) -> list[Problem]:
    problems = []
    if len(frames) == 0:
        return [Problem(rel, "zero frames")]
    if not np.isfinite(fps) or not MIN_FPS <= fps <= MAX_FPS:
        problems.append(Problem(rel, f"fps missing or absurd ({fps}); expected {exp.fps:g}"))
    if len(frames) != exp.num_frames:
        problems.append(Problem(rel, f"{len(frames)} frames; the reference horizon is {exp.num_frames}"))
    if len(frames) > 1 and frames[0].min() == frames[0].max() and (frames == frames[0]).all():  # cheap test first
        problems.append(Problem(rel, "constant video (every pixel of every frame has the same value)"))
    return problems


def check_sizes(sizes: dict[str, tuple[int, int]]) -> list[Problem]:
    """The videos of one instance and seed (relpath → (H, W)) share one resolution, as T1 compares them pixel by
    pixel: those unlike the most common one are named."""
    if not sizes:
        return []
    common = Counter(sizes.values()).most_common(1)[0][0]
    return [Problem(rel, f"{w}×{h} pixels, unlike the {common[1]}×{common[0]} of the other videos of its instance; "
                         "export every video of an instance at one resolution")
            for rel, (h, w) in sizes.items() if (h, w) != common]


def _check_videos(sub: Path, todo: list[Expected]) -> list[Problem]:
    """Each video's problems (decoded one at a time), then one resolution per instance and seed."""
    problems, sizes = [], {}
    for exp in todo:
        video, found = load_video(sub / exp.relpath, exp, exp.relpath)
        problems += found
        if video is not None:
            sizes.setdefault((exp.config, exp.instance_id, exp.seed), {})[exp.relpath] = video[0].shape[1:3]
    return problems + [p for group in sizes.values() for p in check_sizes(group)]


def release_problems(release: Path, configs: list[str]) -> list[Problem]:
    """The files of `configs` that differ from the release's `release.json` (`wsp_eval.integrity`), as fatal
    problems naming each file, the hashes and the fix."""
    found = check_release(release, configs)[1]
    fixes = {c: repair(release, c) for c in {p.path.split("/", 1)[0] for p in found}}
    return [Problem(str(Path(release) / p.path), f"{p.reason}; {fixes[p.path.split('/', 1)[0]]}", fatal=True)
            for p in found]


def named_configs(submission: Path, release: Path) -> list[str]:
    """The configs a submission is to be scored on: its `submission.json`'s "configs" when that is a list of
    names, else the release's test configs (a manifest that cannot be read is `validate`'s to report)."""
    path = Path(submission) / SUBMISSION_JSON
    try:
        named = json.loads(path.read_text()).get("configs") if path.stat().st_size <= MAX_MANIFEST_BYTES else None
    except (OSError, ValueError, AttributeError, RecursionError):
        named = None
    if isinstance(named, list) and named and all(isinstance(c, str) for c in named):
        return named
    return test_configs(release)


def validate(submission: Path, release: Path, *, check_videos: bool = True, verify_release: bool = True) -> list[Problem]:
    """Every problem of a submission against a release (empty list: valid); with `verify_release`, also every
    file of the scored configs that differs from the release's `release.json`."""
    sub = Path(submission)
    if not sub.is_dir():
        return [Problem(str(sub), "submission folder not found")]
    rel_meta = json.loads((Path(release) / RELEASE_JSON).read_text())
    release_configs = test_configs(release)
    meta, problems = _read_manifest(sub, rel_meta["version"], release_configs)
    problems += _links(sub)
    if meta is None:
        return problems
    configs = meta.get("configs", release_configs)
    absent = [c for c in configs if not (Path(release) / c / INSTANCES).is_file()]
    if absent:  # a partial download of the release: nothing to check the submission against for these configs
        return problems + [Problem(str(Path(release) / c / INSTANCES), f"not in the release folder, though its "
                                   f"{RELEASE_JSON} lists {c} (a partial download?); fetch that config, or name only "
                                   f"the configs you score in {SUBMISSION_JSON}'s \"configs\"", fatal=True)
                           for c in absent]
    if verify_release and (damaged := release_problems(release, configs)):
        return problems + damaged  # a changed release is nothing to check a submission against
    expected = {e.relpath: e for e in expected_videos(release, configs, meta["seeds"])}
    present = {_shown(p, sub) for p in sub.rglob("*") if p.is_file() and not p.is_symlink()}
    present -= {SUBMISSION_JSON, LOCK_NAME}
    for rel in sorted(set(expected) - present):
        problems.append(Problem(rel, "missing"))
    for rel in sorted(present - set(expected)):
        why = "unexpected file" if re.fullmatch(r"[\w.-]+/episode_\d{6}/seed\d+\.mp4", rel) is None else \
            "unexpected video (no such episode or seed in the release)"
        problems.append(Problem(rel, why))
    if check_videos:
        problems += _check_videos(sub, [expected[rel] for rel in sorted(set(expected) & present)])
    return problems
