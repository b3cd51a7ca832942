"""Crash-safe per-slot staging: the resumable state of a build.

A builder decides slots one at a time. A decided slot is a folder `slot_NNNNNN/` holding `slot.json`
(its attempts, drop reasons and, when kept, the instance row) and one `<role>.npz` per rollout: its episode
arrays, its video already encoded as the release holds it and its label masks as PNGs (`wsp_data.episode_codec`;
the worker that decides the slot encodes, so assembly only writes). The folder is written under a temporary name
and renamed into place, so a killed build loses at most the slot in flight and never leaves a half-written slot
behind. Assembly into LeRobot reads only decided slots.
"""

from __future__ import annotations

import io
import json
import os
import shutil
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import numpy as np

from wsp_data.episode_codec import StoredVideo, encode_pngs, encode_video, pack, unpack
from wsp_data.platforms import Rollout

T, R = TypeVar("T"), TypeVar("R")
SLOT_DIR = "slot_{slot:06d}"
SLOT_JSON = "slot.json"
CONFIG_JSON = "build_config.json"
FORMAT_FILE, FORMAT = "staging_format", "2"  # 2: rollouts staged with their pictures encoded (`RolloutArrays.encode`)


@dataclass
class RolloutArrays:
    """A rollout as stored: (T+1)-frame observation arrays and (T)-step action streams."""

    role: str
    seed: int
    rgb: np.ndarray
    mask: np.ndarray  # robot labels per frame
    objects: np.ndarray  # object labels per frame (`Observation.objects`)
    qpos: np.ndarray
    tcp_pose: np.ndarray
    object_poses: np.ndarray
    contacts: np.ndarray
    success: np.ndarray
    actions: np.ndarray  # the platform's native stream
    alt_actions: np.ndarray  # the other stream beside it (ManiSkill: end-effector; LIBERO: joint)
    intrinsic: np.ndarray
    extrinsic: np.ndarray
    video: StoredVideo | None = None  # `rgb` already encoded (a builder that measured the stored frames)

    @classmethod
    def from_rollout(cls, role: str, ro: Rollout, video: StoredVideo | None = None) -> RolloutArrays:
        return cls(role, ro.seed, ro.stack("rgb"), ro.stack("mask"), ro.stack("objects"), ro.stack("qpos"), ro.stack("tcp_pose"),
                   ro.stack("object_poses"), ro.stack("contacts"), ro.stack("success"), ro.actions,
                   ro.alt_actions, ro.intrinsic, ro.extrinsic, video)

    def encode(self, fps: int) -> bytes:
        """The rollout as the npz file it is staged as (`StagedRollout`): the pictures encoded (most of staging's
        cost: a worker encodes, so a driver that only writes the bytes does not serialise the build)."""
        arrays = {k: v for k, v in vars(self).items() if isinstance(v, np.ndarray) and k not in PICTURES}
        video, stats = (self.video.data, self.video.stats) if self.video is not None else encode_video(self.rgb, fps)
        masks, mask_ends = pack(encode_pngs(self.mask))
        objects, object_ends = pack(encode_pngs(self.objects))
        buffer = io.BytesIO()
        np.savez(buffer, role=np.array(self.role), seed=np.array(self.seed), **arrays,
                 video=np.frombuffer(video, np.uint8), **{STATS + k: np.asarray(v) for k, v in stats.items()},
                 mask_pngs=masks, mask_png_ends=mask_ends, object_pngs=objects, object_png_ends=object_ends)
        return buffer.getvalue()


PICTURES = ("rgb", "mask", "objects")  # staged encoded (video, PNGs), not as arrays
STATS = "video_stats."  # the npz key prefix of the video's statistics


@dataclass
class StagedRollout:
    """A rollout as staged (`RolloutArrays.encode`) and assembled: its episode arrays, its video (mp4 bytes and
    LeRobot's statistics of its frames) and its robot and object label masks as one PNG per frame."""

    role: str
    seed: int
    qpos: np.ndarray
    tcp_pose: np.ndarray
    object_poses: np.ndarray
    contacts: np.ndarray
    success: np.ndarray
    actions: np.ndarray
    alt_actions: np.ndarray
    intrinsic: np.ndarray
    extrinsic: np.ndarray
    video: bytes
    video_stats: dict[str, np.ndarray]
    mask_pngs: list[bytes]
    object_pngs: list[bytes]

    @property
    def num_frames(self) -> int:
        return len(self.qpos)

    @classmethod
    def load(cls, path: Path) -> StagedRollout:
        return cls.decode(path.read_bytes())

    @classmethod
    def decode(cls, data: bytes) -> StagedRollout:
        """The rollout `RolloutArrays.encode` staged as `data`."""
        with np.load(io.BytesIO(data)) as z:
            d = {k: z[k] for k in z.files}
        return cls(role=str(d.pop("role")), seed=int(d.pop("seed")), video=d.pop("video").tobytes(),
                   video_stats={k[len(STATS):]: d.pop(k) for k in list(d) if k.startswith(STATS)},
                   mask_pngs=unpack(d.pop("mask_pngs"), d.pop("mask_png_ends")),
                   object_pngs=unpack(d.pop("object_pngs"), d.pop("object_png_ends")), **d)


@dataclass
class SlotRecord:
    """The decision for one slot: every attempt with its outcome, and the kept instance row if any."""

    slot: int
    attempts: list[dict] = field(default_factory=list)
    row: dict | None = None
    roles: list[str] = field(default_factory=list)
    cpu: str = ""  # the CPU type that decided it (`wsp_data.machine.cpu_model`)
    peak_rss_mb: float = 0.0  # the deciding process's peak resident memory once decided (not in the report)

    @property
    def kept(self) -> bool:
        return self.row is not None


class Staging:
    """The staging folder of one config."""

    def __init__(self, root: Path):
        self.root = Path(root)

    def slot_dir(self, slot: int) -> Path:
        return self.root / SLOT_DIR.format(slot=slot)

    def mark_format(self) -> None:
        (self.root / FORMAT_FILE).write_text(FORMAT + "\n")

    def has_current_format(self) -> bool:
        """Whether this wsp staged the folder (an earlier one staged raw frames, which assembly cannot read)."""
        path = self.root / FORMAT_FILE
        return path.exists() and path.read_text().strip() == FORMAT

    def is_decided(self, slot: int) -> bool:
        return (self.slot_dir(slot) / SLOT_JSON).exists()

    def write_encoded(self, record: SlotRecord, rollouts: dict[str, bytes]) -> None:
        """Stage a decided slot whose rollouts are already encoded (`RolloutArrays.encode`, by role)."""
        final = self.slot_dir(record.slot)
        tmp = final.with_name(final.name + f".tmp{os.getpid()}")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        for role, npz in rollouts.items():
            (tmp / f"{role}.npz").write_bytes(npz)
        (tmp / SLOT_JSON).write_text(json.dumps(vars(record), indent=1, sort_keys=True, default=_jsonable))
        shutil.rmtree(final, ignore_errors=True)
        os.replace(tmp, final)

    def read_slot(self, slot: int) -> SlotRecord:
        path = self.slot_dir(slot) / SLOT_JSON
        try:
            return SlotRecord(**json.loads(path.read_text()))
        except (json.JSONDecodeError, TypeError) as e:
            raise ValueError(f"{path}: corrupt slot record ({e}); delete the slot folder to rebuild it") from e

    def read_rollouts(self, slot: int, roles: list[str]) -> list[StagedRollout]:
        return [StagedRollout.load(self.slot_dir(slot) / f"{role}.npz") for role in roles]

    def read_kept(self, records: Iterable[SlotRecord],
                  workers: int = 1) -> Iterator[tuple[SlotRecord, list[StagedRollout]]]:
        """(record, rollouts) of each kept record, in order, read by `workers` threads."""
        kept = (r for r in records if r.kept)
        return ordered_ahead(lambda r: (r, self.read_rollouts(r.slot, r.roles)), kept, workers)

    def clean_partial(self) -> None:
        """Remove slot folders a killed build left under a temporary name."""
        for p in self.root.glob("slot_*.tmp*"):
            shutil.rmtree(p, ignore_errors=True)


def ordered_ahead(fn: Callable[[T], R], items: Iterable[T], workers: int) -> Iterator[R]:
    """`map(fn, items)` run by `workers` threads (zlib, PNG and video codecs release the GIL), in order and at most
    2·`workers` items ahead of the consumer, so memory stays bounded."""
    with ThreadPoolExecutor(max(1, workers)) as pool:
        pending: deque = deque()
        for item in items:
            pending.append(pool.submit(fn, item))
            if len(pending) > 2 * workers:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
