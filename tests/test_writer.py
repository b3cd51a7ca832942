"""Staging and the config writer on synthetic rollouts (no simulator, seconds): a rollout staged in any process gives
the same bytes and reads back whole; one-episode video files packed into LeRobot's files in one pass each, frames
where LeRobot looks for them, and byte-identical output whatever the folder."""

from __future__ import annotations

import hashlib
import io
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from wsp_data.platforms import kit
from wsp_data.staging import RolloutArrays, SlotRecord, StagedRollout
from wsp_data.writer import write_config

PLATFORM, FRAMES = "aloha", 12
FPS = kit(PLATFORM).info.fps


def _rollout(role: str, seed: int) -> RolloutArrays:
    info = kit(PLATFORM).info
    t = np.arange(FRAMES)[:, None, None]
    y, x = np.mgrid[:info.height, :info.width]
    rgb = np.stack(np.broadcast_arrays((x + 7 * t + seed) % 256, (y + 3 * t) % 256, (x + y + 11 * seed) % 256), -1)
    mask = ((x + t) % 64 < 20).astype(np.uint8)
    objects = ((y + t) % 48 < 10).astype(np.uint8)  # object 0's label where it is seen
    state = np.random.default_rng(seed).normal(size=(FRAMES, 14)).astype(np.float32)
    return RolloutArrays(role, seed, rgb.astype(np.uint8), mask, objects, state, state, np.zeros((FRAMES, 4, 7), np.float32),
                         np.zeros((FRAMES, 4), bool), np.arange(FRAMES) == FRAMES - 1, state[1:], state[1:],
                         np.eye(3, dtype=np.float32), np.eye(3, 4, dtype=np.float32))


def _instances() -> list[tuple[SlotRecord, list[RolloutArrays]]]:
    roles = ["reference", "source"]
    return [(SlotRecord(k, row={"instance_id": f"t4_aloha/{k}", "suite": "t4", "task": "transfer_cube",
                                "source": "expert", "instruction": "move the cube", "objects": ["cube"]}, roles=roles),
             [_rollout(role, 10 * k + i) for i, role in enumerate(roles)]) for k in range(3)]


def _staged(instances) -> list[tuple[SlotRecord, list[StagedRollout]]]:
    return [(record, [StagedRollout.decode(r.encode(FPS)) for r in rollouts]) for record, rollouts in instances]


def _encode(r: RolloutArrays) -> bytes:
    return r.encode(FPS)


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_rollout_stages_the_same_bytes_in_any_process_and_reads_back_whole():
    r = _rollout("reference", 3)
    with ProcessPoolExecutor(1, mp_context=get_context("spawn")) as pool:
        assert pool.submit(_encode, r).result() == r.encode(FPS)
    staged = StagedRollout.decode(r.encode(FPS))
    for name in ("qpos", "tcp_pose", "object_poses", "contacts", "success", "actions", "alt_actions", "intrinsic",
                 "extrinsic"):
        assert np.array_equal(getattr(staged, name), getattr(r, name)) and getattr(staged, name).dtype == getattr(
            r, name).dtype, name
    assert (staged.role, staged.seed, staged.num_frames) == ("reference", 3, FRAMES)
    for pngs, labels in ((staged.mask_pngs, r.mask), (staged.object_pngs, r.objects)):
        assert [np.array(Image.open(io.BytesIO(p))).tolist() for p in pngs] == labels.tolist()
    assert staged.video_stats["count"].item() > 0 and staged.video_stats["mean"].shape == (3,)


def test_same_input_gives_the_same_bytes_in_any_folder(tmp_path):
    staged = _staged(_instances())
    for name in ("a", "b"):
        assert write_config(tmp_path / name / "t4_aloha", "t4_aloha", PLATFORM, staged) == 6
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")
    assert not list((tmp_path / "a").rglob("*.writing")) and not list((tmp_path / "a").rglob(".episode-videos"))


@pytest.mark.parametrize("file_mb", [None, 1e-9])  # LeRobot's default: one video file; tiny: one file per episode
def test_packed_videos_hold_every_frame_where_lerobot_looks(tmp_path, monkeypatch, file_mb):
    import lerobot.datasets.utils
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    if file_mb:
        monkeypatch.setattr(lerobot.datasets.utils, "DEFAULT_VIDEO_FILE_SIZE_IN_MB", file_mb)
    instances = _instances()
    write_config(tmp_path / "t4_aloha", "t4_aloha", PLATFORM, _staged(instances))
    ds = LeRobotDataset("worldsimprobe/t4_aloha", root=tmp_path / "t4_aloha")
    files = sorted((tmp_path / "t4_aloha" / "videos").rglob("*.mp4"))
    assert len(files) == (6 if file_mb else 1) and ds.meta.total_episodes == 6 and len(ds) == 6 * FRAMES
    rollouts = [r for _, rs in instances for r in rs]
    for episode, frame in ((0, 0), (3, 5), (5, FRAMES - 1)):
        item = ds[episode * FRAMES + frame]
        assert int(item["episode_index"]) == episode and int(item["frame_index"]) == frame
        decoded = (item[kit(PLATFORM).info.video_key].numpy().transpose(1, 2, 0) * 255).round()
        assert np.abs(decoded - rollouts[episode].rgb[frame]).max() <= 3  # yuv444p crf 0: near lossless
    # the image statistics come from staging (LeRobot's streaming statistics of every frame, on a
    # downsampled copy): per channel, in [0, 1], and the frames' own mean to within the downsampling's 1 %
    stats = ds.meta.stats[kit(PLATFORM).info.video_key]
    frames = np.concatenate([r.rgb for r in rollouts]).reshape(-1, 3) / 255
    assert np.asarray(stats["mean"]).shape == (3, 1, 1)
    np.testing.assert_allclose(np.asarray(stats["mean"]).reshape(3), frames.mean(0), atol=0.01)
    assert (np.asarray(stats["min"]) >= 0).all() and (np.asarray(stats["max"]) <= 1).all()
