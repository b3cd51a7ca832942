"""Read reference rollouts from a release without LeRobot's dataloader or a simulator: episode rows, the
reference video segment of an episode inside its shared v3.0 video file, and the robot and object label masks."""

from __future__ import annotations

import glob
import io
import json
import threading
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq

from wsp_eval.release_format import (BENCHMARK_VERSION, FIRST_FRAME, MASK_COLUMN, MASKS, OBJECT_MASK_COLUMN,
                                     OBJECT_POSES_KEY)
from wsp_eval.video import VideoError


@lru_cache(maxsize=32)
def episodes(config_dir: Path) -> dict[int, dict]:
    """episode_index → its row of meta/episodes (LeRobot columns + wsp.* fields)."""
    rows = {}
    for path in sorted(glob.glob(str(Path(config_dir) / "meta" / "episodes" / "*" / "*.parquet"))):
        cols = [c for c in pq.read_schema(path).names if not c.startswith("stats/")]
        for r in pq.read_table(path, columns=cols).to_pylist():
            rows[r["episode_index"]] = r
    return rows


def video_key_of(info: dict) -> str:
    """The one video feature of a config's `meta/info.json` (the platform's evaluated camera)."""
    keys = [k for k, f in info["features"].items() if f["dtype"] == "video"]
    if len(keys) != 1:
        raise VideoError(f"expected one video feature in meta/info.json, found {keys}")
    return keys[0]


def reference_size(config_dir: Path) -> tuple[int, int] | None:
    """(H, W) of a config's reference video (its one camera), from `meta/info.json`, or in an inputs-only
    release from a first frame's PNG header; None where neither is there."""
    config_dir = Path(config_dir)
    info = config_dir / "meta" / "info.json"
    if info.is_file():
        meta = json.loads(info.read_text())
        h, w = meta["features"][video_key_of(meta)]["shape"][:2]
        return int(h), int(w)
    first = next(iter(sorted((config_dir / Path(FIRST_FRAME).parent).glob("*.png"))), None)
    if first is None:
        return None
    with open(first, "rb") as f:  # PNG: the IHDR chunk's width and height follow the 16-byte signature + header
        header = f.read(24)
    return int.from_bytes(header[20:24], "big"), int.from_bytes(header[16:20], "big")


class _SharedVideo:
    """One open reference video file, shared by every reader in this thread (`_open_video`): opening a paper-count
    config's file (tens of thousands of frames) parses its index for 10–15 ms, once per instance otherwise. A
    reader that finds another has used the file since its last frame seeks again (`user`). Per thread, because
    FFmpeg aborts when two threads decode one container (the rating page serves media from several threads)."""

    def __init__(self, path: str):
        import av

        self.container = av.open(path)
        self.stream = self.container.streams.video[0]
        self.user: object | None = None


@lru_cache(maxsize=4)
def _open_video(path: str, mtime_ns: int, size: int, thread: int) -> _SharedVideo:
    return _SharedVideo(path)


def iter_reference_frames(config_dir: Path, episode_index: int) -> Iterator[np.ndarray]:
    """The reference video of one episode, frame by frame (RGB uint8 (H, W, 3)), decoded from its shared file
    only as far as the caller reads; a VideoError when the file is unreadable or holds too few frames. Readers of
    the same file take turns on one open container: each seeks to its next frame whenever another has read in
    between (decoding from the keyframe before it), so the frames are those of a reader of its own."""
    import av

    config_dir = Path(config_dir)
    ep = episodes(config_dir)[episode_index]
    info = json.loads((config_dir / "meta" / "info.json").read_text())
    video_key = video_key_of(info)
    key = f"videos/{video_key}"
    path = config_dir / info["video_path"].format(video_key=video_key, chunk_index=ep[f"{key}/chunk_index"],
                                                  file_index=ep[f"{key}/file_index"])
    start, fps, n = ep[f"{key}/from_timestamp"], info["fps"], ep["length"]
    first = int(round(start * fps))
    found, me = 0, object()
    try:
        stat = path.stat()
        video = _open_video(str(path), stat.st_mtime_ns, stat.st_size, threading.get_ident())
        seek_to = start
        while found < n:
            video.user = me
            stream = video.stream
            video.container.seek(int(seek_to / stream.time_base), stream=stream, backward=True, any_frame=False)
            moved = False
            for f in video.container.decode(stream):
                j = int(round(float(f.pts * stream.time_base) * fps))
                if j >= first + n:
                    break
                if j >= first + found:
                    found += 1
                    yield f.to_ndarray(format="rgb24")
                    if video.user is not me:  # another reader used the file meanwhile: seek to the next frame
                        moved, seek_to = True, (first + found) / fps
                        break
            if not moved:
                break
    except (av.error.FFmpegError, OSError) as e:
        _open_video.cache_clear()  # a damaged container is not reused
        raise VideoError(f"{path}: unreadable reference video ({e})") from e
    if found != n:
        raise VideoError(f"{path}: episode {episode_index} has {found} decodable frames, expected {n}")


def reference_frames(config_dir: Path, episode_index: int) -> np.ndarray:
    """The reference video of one episode, RGB uint8 (length, H, W, 3), decoded from its shared file."""
    return np.stack(list(iter_reference_frames(config_dir, episode_index)))


def reference_masks(config_dir: Path, episode_index: int, first_only: bool = False) -> np.ndarray:
    """The robot label masks of one episode (length, H, W) uint8: 0 not robot, 1 arm, 2 wrist/hand/fingers; with
    `first_only`, frame 0's alone (1, H, W)."""
    return _label_images(Path(config_dir), episode_index, MASK_COLUMN, first_only)


def reference_object_masks(config_dir: Path, episode_index: int) -> np.ndarray:
    """The object label masks of one episode (length, H, W) uint8: k + 1 where object k of the episode's
    `wsp.objects` is the visible surface, else 0."""
    return _label_images(Path(config_dir), episode_index, OBJECT_MASK_COLUMN, False)


def _label_images(config_dir: Path, episode_index: int, column: str, first_only: bool) -> np.ndarray:
    """One episode's PNG label images of `column` in the config's masks file, decoded in frame order."""
    from PIL import Image

    path = config_dir / MASKS
    if not path.exists():
        raise VideoError(f"{path}: missing; this release is not of format {BENCHMARK_VERSION}: rebuild it with "
                         "this version of worldsimprobe (`wsp build`)")
    stat = path.stat()
    masks, groups = _mask_row_groups(str(path), stat.st_mtime_ns, stat.st_size)
    columns = ["episode_index", "frame_index", column]
    t = (masks.read(columns=columns) if groups is None
         else masks.read_row_groups(groups.get(episode_index, []), columns=columns))
    keep = pc.equal(t["episode_index"], episode_index)
    if first_only:
        keep = pc.and_(keep, pc.equal(t["frame_index"], 0))
    cells = t.filter(keep).sort_by("frame_index").column(column).to_pylist()
    n = 1 if first_only else episodes(config_dir)[episode_index]["length"]
    if len(cells) != n:
        raise VideoError(f"{path}: episode {episode_index} has {len(cells)} {column} images, expected {n}")
    return np.stack([np.asarray(Image.open(io.BytesIO(c))) for c in cells])


@lru_cache(maxsize=8)
def _mask_row_groups(path: str, mtime_ns: int, size: int) -> tuple[pq.ParquetFile, dict[int, list[int]] | None]:
    """A masks file opened once per process (keyed by its path, mtime and size) and the row groups that may hold
    each episode, from their `episode_index` statistics (the writer writes one row group per episode): a scoring
    worker reads one episode's row group instead of parsing the file's footer (≈ 1,300 row groups at a paper
    count) for every instance. None when a row group has no statistics: then every row group is read."""
    masks = pq.ParquetFile(path)
    column = masks.schema_arrow.get_field_index("episode_index")
    groups: dict[int, list[int]] = {}
    for g in range(masks.metadata.num_row_groups):
        stats = masks.metadata.row_group(g).column(column).statistics
        if stats is None or not stats.has_min_max:
            return masks, None
        for episode in range(int(stats.min), int(stats.max) + 1):
            groups.setdefault(episode, []).append(g)
    return masks, groups


def reference_object_poses(config_dir: Path, episode_index: int) -> np.ndarray:
    """One episode's stored object poses in frame order (`object_poses`)."""
    path = Path(config_dir) / "data"
    try:
        t = pq.read_table(path, columns=["episode_index", "frame_index", OBJECT_POSES_KEY],
                          filters=[("episode_index", "=", episode_index)])
    except (OSError, KeyError, ValueError) as e:
        raise VideoError(f"{path}: cannot read {OBJECT_POSES_KEY} ({e})") from None
    cells = t.sort_by("frame_index").column(OBJECT_POSES_KEY).to_pylist()
    n = episodes(config_dir)[episode_index]["length"]
    if len(cells) != n:
        raise VideoError(f"{path}: episode {episode_index} has {len(cells)} {OBJECT_POSES_KEY} rows, expected {n}")
    return object_poses(np.array(cells))


def object_poses(stored: np.ndarray) -> np.ndarray:
    """Stored `sim.object_poses` rows (T, MAX_OBJECTS·7) → (T, MAX_OBJECTS, 7) float64 with each unused slot
    (all zeros: a quaternion of norm 0, which no real pose has) NaN, the builders' in-memory convention."""
    poses = np.asarray(stored, dtype=np.float64).reshape(len(stored), -1, 7).copy()
    poses[:, ~(np.linalg.norm(poses[0, :, 3:], axis=-1) > 0)] = np.nan
    return poses
