"""A rollout's pictures as the release holds them: the video by LeRobot's own streaming encoder with the reference
codec (near-lossless h264 yuv444p, crf 0) on one x264 thread, with LeRobot's per-channel statistics of its frames,
and the robot and object label masks as PNG files. One x264 thread gives the same bytes in any process, so the
worker that decides a slot encodes its rollouts and assembly only writes them. A builder that measures a quantity
the scorer will compare (T4's motion gate) measures it on `stored_video`'s frames, the pictures the scorer reads."""

from __future__ import annotations

import io
import tempfile
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

REFERENCE_VIDEO_CODEC = dict(vcodec="h264", pix_fmt="yuv444p", crf=0)


def encode_video(rgb: np.ndarray, fps: int) -> tuple[bytes, dict[str, np.ndarray]]:
    """The mp4 of `rgb` ((T, H, W, 3) uint8) and LeRobot's statistics of its frames."""
    import av
    from lerobot.configs.video import RGBEncoderConfig
    from lerobot.datasets.video_utils import StreamingVideoEncoder

    encoder = StreamingVideoEncoder(fps, RGBEncoderConfig(**REFERENCE_VIDEO_CODEC), queue_maxsize=len(rgb) + 1,
                                    encoder_threads=1)  # the queue holds every frame: none is ever dropped
    with tempfile.TemporaryDirectory(prefix="wsp-video-") as folder:
        encoder.start_episode(["video"], Path(folder))
        for frame in rgb:
            encoder.feed_frame("video", frame)
        path, stats = encoder.finish_episode()["video"]
        with av.open(str(path)) as container:
            frames = container.streams.video[0].frames
        if stats is None or frames != len(rgb):
            raise RuntimeError(f"the video encoder wrote {frames} of {len(rgb)} frames")
        return path.read_bytes(), stats


@dataclass(frozen=True)
class StoredVideo:
    """A rollout's video as the release stores it (`encode_video`); `frames` decodes it on first use as the scorer
    reads a reference (PyAV, rgb24): near-lossless, yet a level off here and there, which is enough to move a
    chained tracker."""

    data: bytes = field(repr=False)
    stats: dict[str, np.ndarray] = field(repr=False)
    shape: tuple[int, ...]  # of the rendered frames (T, H, W, 3)

    @cached_property
    def frames(self) -> np.ndarray:
        import av

        with av.open(io.BytesIO(self.data)) as container:
            frames = np.stack([f.to_ndarray(format="rgb24") for f in container.decode(video=0)])
        if frames.shape != self.shape:
            raise RuntimeError(f"the stored video decodes to {frames.shape}, not the rendered {self.shape}")
        return frames


def stored_video(rgb: np.ndarray, fps: int) -> StoredVideo:
    """`rgb` ((T, H, W, 3) uint8) encoded as the release stores it."""
    return StoredVideo(*encode_video(rgb, fps), rgb.shape)


def encode_pngs(labels: np.ndarray) -> list[bytes]:
    """One PNG (8-bit grey) per frame of `labels` ((T, H, W))."""
    from PIL import Image

    def png(m: np.ndarray) -> bytes:
        buf = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(m, dtype=np.uint8), mode="L").save(buf, format="PNG")
        return buf.getvalue()

    return [png(m) for m in labels]


def pack(blobs: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """Byte strings as one uint8 array and the end offset of each (an npz holds no list of bytes)."""
    return (np.frombuffer(b"".join(blobs), np.uint8),
            np.cumsum([len(b) for b in blobs], dtype=np.int64))


def unpack(data: np.ndarray, ends: np.ndarray) -> list[bytes]:
    raw = data.tobytes()
    return [raw[a:b] for a, b in zip([0, *ends[:-1].tolist()], ends.tolist(), strict=True)]
