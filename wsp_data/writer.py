"""Assemble staged slots into one config of a release: a LeRobot v3.0 dataset written through lerobot's
own API (near-lossless h264 yuv444p crf 0 video), `wsp.*` episode columns in its episode table,
`masks.parquet` (PNG robot and object label masks, outside LeRobot's features) and `instances.parquet` (one row per
instance).

Writes are deterministic (same staged input → byte-identical files in any folder) and atomic per config: the
dataset is written beside its final place and swapped in when complete. LeRobot appends each episode's video to
its file by re-muxing the whole file, quadratic in episodes per file; so it writes one video file per episode
here, and `_pack_videos` joins them into files of LeRobot's default size, each muxed once (linear).

The pictures arrive encoded: the worker that decided a slot encoded its videos (with their image statistics) and
label masks when it staged them (`wsp_data.episode_codec`), on as many processes or Ray nodes as the slots. What
is left here is serial, as LeRobot writes its dataset files in episode order: its frame table, episode metadata
and running statistics. It takes the finished videos through LeRobot's streaming-encoder interface
(`_AheadVideos`).
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import shutil
from collections import deque
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from wsp_data.episode_codec import REFERENCE_VIDEO_CODEC
from wsp_data.platforms import kit
from wsp_data.schema import (
    CONTACTS_KEY, EPISODE_ID, INSTANCES, MASK_COLUMN, MASKS, OBJECT_MASK_COLUMN, OBJECT_POSES_KEY, SOURCE_ROLE,
    PlatformInfo,
    frame_features,
)
from wsp_data.staging import SlotRecord, StagedRollout

EPISODE_TABLES = "meta/episodes/*/*.parquet"  # LeRobot's episode table files
ONE_EPISODE_PER_FILE = 1e-9  # a video file size limit (MB) every episode exceeds: LeRobot starts a new file for each
Instance = tuple[SlotRecord, list[StagedRollout]]  # a kept slot and its rollouts
EPISODE_VIDEOS = ".episode-videos"  # where each staged video waits for LeRobot to move it into the dataset
TRAIN_SPLIT, TEST_SPLIT = "train", "test"  # LeRobot info.json `splits`: training configs, scored configs


def _frames(r: StagedRollout, instruction: str, info: PlatformInfo, picture: np.ndarray):
    """LeRobot frames of `r`; the video key holds `picture` (a blank of the frame's shape: LeRobot checks its
    shape and hands it to `_AheadVideos`, which ignores it, as the video is already encoded)."""
    last = len(r.actions) - 1
    for t in range(r.num_frames):
        a = min(t, last)  # the final frame repeats the last action (never executed)
        yield {
            info.video_key: picture,
            "observation.state": r.qpos[t],
            "observation.ee_pose": r.tcp_pose[t],
            OBJECT_POSES_KEY: np.nan_to_num(r.object_poses[t], nan=0.0).reshape(-1),  # unused slots: zeros
            CONTACTS_KEY: r.contacts[t].astype(np.float32),
            "action": r.actions[a],
            info.alt_action_key: r.alt_actions[a],
            "next.success": np.array([r.success[t]]),
            "task": instruction,
        }


def write_config(config_dir: Path, config: str, platform: str, instances: Iterable[Instance]) -> int:
    """Write `config_dir` from kept slots (in slot order); returns the number of episodes written."""
    from lerobot.configs.video import RGBEncoderConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.datasets.video_utils import StreamingVideoEncoder

    info = kit(platform).info
    tmp = config_dir.with_name(config_dir.name + ".writing")
    shutil.rmtree(tmp, ignore_errors=True)
    logging.getLogger("lerobot").setLevel(logging.WARNING)
    features = frame_features(info)
    ds = LeRobotDataset.create(
        f"worldsimprobe/{config}", fps=info.fps, features=features, root=tmp,
        robot_type=info.robot_type, use_videos=True, rgb_encoder=RGBEncoderConfig(**REFERENCE_VIDEO_CODEC),
        video_files_size_in_mb=ONE_EPISODE_PER_FILE, streaming_encoding=True,
    )
    if not isinstance(getattr(ds.writer, "_streaming_encoder", None), StreamingVideoEncoder):
        raise RuntimeError("this lerobot's dataset writer has no streaming encoder to hand encoded videos to; "
                           "install the lerobot version pinned in pyproject.toml")
    ahead = ds.writer._streaming_encoder = _AheadVideos(info.video_key)
    picture = np.zeros(features[info.video_key]["shape"], np.uint8)
    videos = tmp / EPISODE_VIDEOS
    videos.mkdir()
    episode_rows: list[dict] = []
    instance_rows: list[dict] = []
    with contextlib.closing(_MaskWriter(tmp / MASKS)) as masks:  # closed also when a step below raises
        for record, rollouts in instances:
            row = dict(record.row)
            indices = []
            for r in rollouts:
                index = len(episode_rows)
                video = videos / f"{index:06d}" / "video.mp4"  # a folder each: LeRobot removes it with the video
                video.parent.mkdir()
                video.write_bytes(r.video)
                ahead.ready.append((video, r.video_stats))
                with contextlib.redirect_stderr(io.StringIO()):
                    for frame in _frames(r, row["instruction"], info, picture):
                        ds.add_frame(frame)
                    ds.save_episode(parallel_encoding=False)
                masks.add(index, r.mask_pngs, r.object_pngs)
                indices.append(index)
                episode_rows.append({
                    "wsp.episode_id": EPISODE_ID.format(index=index), "wsp.instance_id": row["instance_id"],
                    "wsp.suite": row["suite"], "wsp.platform": platform, "wsp.task": row["task"],
                    "wsp.seed": int(r.seed), "wsp.role": r.role, "wsp.source": row["source"],
                    "wsp.intervention": json.dumps(row.get("interventions", {}).get(r.role, {}), sort_keys=True),
                    "wsp.objects": list(row["objects"]),
                    "wsp.camera_intrinsic": r.intrinsic.reshape(-1).astype(float).tolist(),
                    "wsp.camera_extrinsic": r.extrinsic.reshape(-1).astype(float).tolist(),
                    "wsp.success": bool(r.success[-1]), "wsp.num_frames": int(r.num_frames),
                })
            scored = [(r, i) for r, i in zip(rollouts, indices) if r.role != SOURCE_ROLE]
            row.update(
                roles=[r.role for r, _ in scored], episode_indices=[i for _, i in scored],
                episode_ids=[EPISODE_ID.format(index=i) for _, i in scored],
                num_frames=[int(r.num_frames) for r, _ in scored], success=[bool(r.success[-1]) for r, _ in scored],
                fps=info.fps, camera_intrinsic=scored[0][0].intrinsic.reshape(-1).astype(float).tolist(),
                camera_extrinsic=scored[0][0].extrinsic.reshape(-1).astype(float).tolist(),
            )
            source = [i for r, i in zip(rollouts, indices) if r.role == SOURCE_ROLE]
            if source:
                row.update(source_episode_index=source[0], source_episode_id=EPISODE_ID.format(index=source[0]))
            instance_rows.append(row)
        ds.finalize()
    videos.rmdir()  # LeRobot moved every video into the dataset and removed its folder
    for row, video in zip(episode_rows, _pack_videos(tmp, info.video_key), strict=True):
        row.update(video)
    _set_info(tmp / "meta" / "info.json", TRAIN_SPLIT if config.startswith("train_") else TEST_SPLIT)
    _drop_fingerprints(tmp)
    _append_episode_columns(tmp, episode_rows)
    _canonicalize_json(tmp / "meta" / "stats.json")
    write_instances(tmp / INSTANCES, instance_rows)
    shutil.rmtree(config_dir, ignore_errors=True)
    tmp.rename(config_dir)
    return len(episode_rows)


class _AheadVideos:
    """Stands in for LeRobot's `StreamingVideoEncoder` inside its dataset writer: the episode's video was encoded
    when its slot was staged, so the frames fed here are ignored and `finish_episode` hands over the finished file."""

    def __init__(self, key: str):
        self.key, self.ready = key, deque()

    def start_episode(self, video_keys: list[str], temp_dir: Path, depth_video_keys: list[str] | None = None) -> None:
        if list(video_keys) != [self.key]:
            raise RuntimeError(f"expected the one video feature {self.key}, got {video_keys}")

    def feed_frame(self, video_key: str, image: np.ndarray) -> None:
        pass

    def finish_episode(self) -> dict[str, tuple[Path, dict]]:
        return {self.key: self.ready.popleft()}

    def cancel_episode(self) -> None:
        pass

    def close(self) -> None:
        pass


class _MaskWriter:
    """`masks.parquet`, one row per frame in LeRobot's global frame order, written an episode at a time."""

    SCHEMA = pa.schema([("index", pa.int64()), ("episode_index", pa.int64()), ("frame_index", pa.int64()),
                        (MASK_COLUMN, pa.binary()), (OBJECT_MASK_COLUMN, pa.binary())])

    def __init__(self, path: Path):
        self.writer = pq.ParquetWriter(path, self.SCHEMA)
        self.next_index = 0

    def add(self, episode_index: int, pngs: list[bytes], object_pngs: list[bytes]) -> None:
        n = len(pngs)
        self.writer.write_table(pa.table({
            "index": np.arange(self.next_index, self.next_index + n, dtype=np.int64),
            "episode_index": np.full(n, episode_index, dtype=np.int64), "frame_index": np.arange(n, dtype=np.int64),
            MASK_COLUMN: pa.array(pngs, pa.binary()),
            OBJECT_MASK_COLUMN: pa.array(object_pngs, pa.binary())}, schema=self.SCHEMA))  # one row group per episode
        self.next_index += n

    def close(self) -> None:
        self.writer.close()


def _pack_videos(root: Path, key: str) -> list[dict]:
    """Join the one-episode video files of `key` into files of up to LeRobot's default size (a new file when the
    next episode would reach it, as LeRobot does), each muxed in one pass; returns every episode's new
    `videos/<key>/*` columns, in episode order."""
    from lerobot.datasets.utils import DEFAULT_VIDEO_FILE_SIZE_IN_MB, DEFAULT_VIDEO_PATH, update_chunk_file_indices
    from lerobot.datasets.video_utils import concatenate_video_files

    def path(base: Path, chunk: int, file: int) -> Path:
        return base / DEFAULT_VIDEO_PATH.format(video_key=key, chunk_index=chunk, file_index=file)

    col = f"videos/{key}/"
    names = ["episode_index", col + "chunk_index", col + "file_index", col + "to_timestamp"]
    table = pa.concat_tables(pq.read_table(p).select(names) for p in sorted(root.glob(EPISODE_TABLES)))
    loose = root / ".videos-per-episode"
    loose.mkdir()
    (root / "videos").rename(loose / "videos")
    chunks_size = json.loads((root / "meta" / "info.json").read_text())["chunks_size"]
    chunk, file, size, group, columns = 0, 0, 0.0, [], []
    for _, src_chunk, src_file, duration in sorted(zip(*table.to_pydict().values())):  # in episode order
        src = path(loose, src_chunk, src_file)
        mb = src.stat().st_size / 1024**2
        if group and size + mb >= DEFAULT_VIDEO_FILE_SIZE_IN_MB:
            concatenate_video_files(group, path(root, chunk, file))
            chunk, file = update_chunk_file_indices(chunk, file, chunks_size)
            group, size = [], 0.0
        start = columns[-1][col + "to_timestamp"] if group else 0.0
        group.append(src)
        size += mb
        columns.append({col + "chunk_index": chunk, col + "file_index": file, col + "from_timestamp": start,
                        col + "to_timestamp": start + duration})
    concatenate_video_files(group, path(root, chunk, file))
    shutil.rmtree(loose)
    return columns


def _append_episode_columns(root: Path, rows: list[dict]) -> None:
    """Set the `wsp.*` episode-level fields and the packed video columns in LeRobot's meta/episodes files."""
    for path in sorted(root.glob(EPISODE_TABLES)):
        table = pq.read_table(path)
        eps = table.column("episode_index").to_pylist()
        for key in rows[0] if rows else ():
            values = pa.array([rows[e][key] for e in eps])
            i = table.schema.get_field_index(key)
            table = (table.append_column(key, values) if i < 0
                     else table.set_column(i, key, values.cast(table.schema.field(i).type)))
        pq.write_table(table, path)


def _drop_fingerprints(root: Path) -> None:
    """`datasets` stores a fingerprint derived from the output path in each data file's metadata; drop it so
    the same build written to another folder is byte-identical."""
    for path in sorted(root.glob("data/*/*.parquet")):
        table = pq.read_table(path)
        meta = dict(table.schema.metadata or {})
        if b"huggingface" in meta:
            hf = json.loads(meta[b"huggingface"])
            hf.pop("fingerprint", None)
            meta[b"huggingface"] = json.dumps(hf).encode()
            pq.write_table(table.replace_schema_metadata(meta), path)


def _set_info(info_path: Path, split: str) -> None:
    """LeRobot names every episode `train`; a test config's episodes are the `test` split (the card says so too).
    The video files were packed to LeRobot's default size."""
    from lerobot.datasets.utils import DEFAULT_VIDEO_FILE_SIZE_IN_MB

    info = json.loads(info_path.read_text())
    info["splits"] = {split: f"0:{info['total_episodes']}"}
    info["video_files_size_in_mb"] = DEFAULT_VIDEO_FILE_SIZE_IN_MB
    info_path.write_text(json.dumps(info, indent=4))


def _canonicalize_json(path: Path) -> None:
    """lerobot writes stats keys in hash order; sort them so rebuilds are byte-identical."""
    path.write_text(json.dumps(json.loads(path.read_text()), indent=4, sort_keys=True))


def write_instances(path: Path, rows: list[dict]) -> None:
    if not rows:
        raise ValueError(f"{path}: no instances to write")
    table = pa.Table.from_pylist([{k: _plain(v) for k, v in sorted(r.items())} for r in rows])
    pq.write_table(table, path)


def _plain(v):
    if isinstance(v, dict):
        return json.dumps(v, sort_keys=True)  # intervention parameters etc.: one JSON string column
    if isinstance(v, np.generic):
        return v.item()
    return v
