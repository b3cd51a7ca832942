"""Timestamps and nearest-frame resampling (spec §4.1), and the temporally aligned MSE of T1 (spec §3.1)."""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np


def timestamps(num_frames: int, fps: float) -> np.ndarray:
    """Frame j of a video without explicit timestamps sits at j / fps; every video starts at t = 0."""
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    return np.arange(num_frames, dtype=np.float64) / fps


def nearest_indices(source_ts: np.ndarray, target_ts: np.ndarray) -> np.ndarray:
    """For each target timestamp, the index of the nearest source frame (ties go to the earlier frame)."""
    source_ts = np.asarray(source_ts, dtype=np.float64)
    idx = np.clip(np.searchsorted(source_ts, target_ts), 1, len(source_ts) - 1)
    left, right = source_ts[idx - 1], source_ts[idx]
    return np.where(np.abs(target_ts - left) <= np.abs(right - target_ts), idx - 1, idx)


def aligned_mse(base: np.ndarray, other: np.ndarray, base_fps: float, other_fps: float) -> float:
    """D(base, other): `base`'s timestamps are the timebase; keep those within the common duration (up to
    the earlier of the two last-frame timestamps), take `other`'s nearest frame at each, average the
    squared difference over frames, pixels and channels (0–255 scale). No warping, no phase search."""
    if len(base) == 0 or len(other) == 0:
        raise ValueError("aligned_mse needs two non-empty videos")
    tb, to = timestamps(len(base), base_fps), timestamps(len(other), other_fps)
    keep = tb <= min(tb[-1], to[-1]) + 1e-9
    j = nearest_indices(to, tb[keep]) if len(other) > 1 else np.zeros(int(keep.sum()), dtype=int)
    a, b = np.ascontiguousarray(base[keep]), np.ascontiguousarray(other[j])
    if a.dtype == np.uint8 and b.dtype == np.uint8:  # OpenCV's sum of squared differences: ~40× numpy's
        import cv2

        return float(cv2.norm(a.reshape(len(a), -1), b.reshape(len(b), -1), cv2.NORM_L2SQR) / a.size)
    diff = a.astype(np.float64) - b.astype(np.float64)
    return float(np.mean(diff * diff))


class VideoError(ValueError):
    """A video that cannot be used; the message names the file."""


MIN_FPS, MAX_FPS = 1.0, 240.0  # a submission's fps outside this range is treated as absurd
REEXPORT = "re-export it as an h264 mp4 (`wsp_eval.video.write_video` writes the accepted encoding)"
LOSSLESS_FIX = ("save the model's frames losslessly: `wsp generate` and `wsp_eval.video.write_video` do (h264 RGB, "
                "crf 0), as does `ffmpeg -i FRAMES -c:v libx264rgb -crf 0 -tune fastdecode seedK.mp4`; "
                "re-encoding a lossy file losslessly keeps its codec noise, so export from the frames the model produced")
"""The submission's encoding contract (spec §4.7; docs/submission.md): every frame exactly as
the model produced it. Lossy codecs and chroma subsampling add noise that T1 reads as action compression (the
oracle as h264 yuv420p crf 23 falls from 99.9 to 43 on T1), so they are refused before decoding."""
MAX_SIDE = 512
"""The largest width or height of a submitted video. The largest reference camera is 320×240 (RoboTwin;
ManiSkill and LIBERO render 128×128, spec §2), T2/T3 compare flows at 160×120 and T4 tracks in 256², so more
pixels score nothing; 512 admits the usual generation sizes (256², 512²) and bounds a decoded frame to
768 KiB, so a video of a reference's horizon (a few hundred frames) stays a few hundred MB at most, where one
1920×1080 frame is 6 MiB and an upload of 2,900 of them needed 24 GB."""
FIRST_ALLOCATION = 256  # frames allocated at most up front when no horizon bounds the video (`_decode` grows it)
MERGE_CHUNK = 16  # planar frames interleaved per `cv2.merge` call (`_Planar`) …
CHUNK_MAX_PIXELS = 192 * 192  # … when a frame has at most this many pixels (128² gains; 320×240 loses: `_Planar`)


def read_video(path, max_frames: int | None = None, max_side: int = MAX_SIDE,
               lossless: bool = False) -> tuple[np.ndarray, float]:
    """Decode a video file as RGB uint8 (N, H, W, 3) and return it with its fps, in bounded memory: with
    `max_frames` (the reference horizon) the file size and the stream header's frame count are checked before
    decoding and decoding stops at the first frame past it (a header can lie: frames are counted); the header's
    resolution and every decoded frame's are checked against `max_side`; with `lossless` the stream must be
    lossless (`encoding_problem`). A VideoError names the file, what was found, what is allowed and the fix."""
    import av

    if max_frames is not None:
        _check_size(path, max_frames, max_side)
    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                raise VideoError(f"{path}: no video stream; {REEXPORT}")
            stream = container.streams.video[0]
            _check_header(path, stream, max_frames, max_side)
            if lossless and (why := encoding_problem(stream)) is not None:
                raise VideoError(f"{path}: {why}; {LOSSLESS_FIX}")
            rate = stream.average_rate or stream.guessed_rate
            frames = _decode(path, container.decode(stream), max_frames, max_side, stream.frames)
    except VideoError:
        raise
    except (av.error.FFmpegError, OSError, ValueError) as e:
        raise VideoError(f"{path}: unreadable video ({type(e).__name__}: {e}); {REEXPORT}") from e
    fps = float(rate) if rate else float("nan")
    return frames, fps


def _too_many(path, found: str, max_frames: int) -> VideoError:
    return VideoError(f"{path}: {found}; the reference horizon is {max_frames}: export exactly {max_frames} "
                      "frames (frame j at j/fps)")


def _check_size(path, max_frames: int, max_side: int) -> None:
    """Refuse a file larger than twice `max_frames` raw RGB frames at the cap (+1 MiB), more than even lossless
    h264 of noise takes, unopened: it cannot be a valid video and its index alone would cost memory."""
    limit = max_frames * 2 * max_side * max_side * 3 + (1 << 20)
    size = os.path.getsize(path)
    if size > limit:
        raise VideoError(f"{path}: {size / 1e6:.1f} MB, more than {max_frames} frames of at most {max_side}×"
                         f"{max_side} take even lossless ({limit / 1e6:.1f} MB); export exactly {max_frames} "
                         "frames at the reference's resolution")


def _check_side(path, width: int, height: int, max_side: int) -> None:
    if max(width, height) > max_side:
        raise VideoError(f"{path}: {width}×{height} pixels; at most {max_side} per side is accepted (references "
                         "are at most 320×240): export at the reference's resolution (the first frame's size)")


def _check_header(path, stream, max_frames: int | None, max_side: int) -> None:
    """Refuse from the header alone, before any frame is decoded (0 means the header does not say)."""
    _check_side(path, stream.codec_context.width, stream.codec_context.height, max_side)
    if max_frames is not None and stream.frames > max_frames:
        raise _too_many(path, f"{stream.frames} frames (stream header)", max_frames)


def encoding_problem(stream) -> str | None:
    """Why a video stream is not lossless, from its codec parameters alone (None: accepted). Accepted: PNG, and
    H.264 whose sequence parameter set is 4:4:4 (RGB or YUV, no chroma subsampling) with the lossless flag
    (`qpprime_y_zero_transform_bypass_flag`, set by x264 at qp 0 / crf 0)."""
    cc = stream.codec_context
    if cc.name == "png":
        return None
    if cc.name != "h264":
        return f"{cc.name} video is not an accepted encoding (lossless h264 or png)"
    sps = h264_sps(bytes(cc.extradata or b""))
    if sps is None:
        return "h264 without a readable sequence parameter set, so it cannot be shown to be lossless"
    chroma_format, lossless_flag = sps
    if chroma_format != 3:
        kind = {0: "monochrome", 1: "4:2:0", 2: "4:2:2"}.get(chroma_format, str(chroma_format))
        return f"chroma-subsampled h264 ({kind}, pix_fmt {cc.pix_fmt}): colour is stored at reduced resolution"
    if not lossless_flag:
        return f"lossy h264 (pix_fmt {cc.pix_fmt}, quantised: crf or qp above 0)"
    return None


_HIGH_PROFILES = {100, 110, 122, 244, 44, 83, 86, 118, 128, 138, 139, 134, 135}


def h264_sps(extradata: bytes) -> tuple[int, int] | None:
    """(chroma_format_idc, qpprime_y_zero_transform_bypass_flag) of the first sequence parameter set in H.264
    extradata (mp4 `avcC` or Annex B), per ITU-T H.264 §7.3.2.1.1; None when there is none or it is malformed."""
    try:
        if extradata[:1] == b"\x01" and len(extradata) > 8 and extradata[5] & 0x1F:  # avcC
            nal = extradata[8:8 + int.from_bytes(extradata[6:8], "big")]
        else:  # Annex B: start-code-separated NAL units
            nal = next((u for u in extradata.replace(b"\x00\x00\x01", b"\x00\x00\x00\x01").split(b"\x00\x00\x00\x01")
                        if u and u[0] & 0x1F == 7), b"")
        if not nal or nal[0] & 0x1F != 7:
            return None
        bits = _Bits(_unescape(nal[1:]))
        profile = bits.u(8)
        bits.u(16)  # constraint flags, level
        bits.ue()  # seq_parameter_set_id
        if profile not in _HIGH_PROFILES:
            return 1, 0  # baseline / main / extended: 4:2:0, never lossless
        chroma_format = bits.ue()
        if chroma_format == 3:
            bits.u(1)  # separate_colour_plane_flag
        bits.ue(), bits.ue()  # bit depths
        return chroma_format, bits.u(1)
    except (IndexError, ValueError):
        return None


def _unescape(payload: bytes) -> bytes:
    """The RBSP of a NAL payload: every emulation-prevention byte (0x03 after two zero bytes) removed."""
    out, zeros = bytearray(), 0
    for b in payload:
        if zeros >= 2 and b == 3:
            zeros = 0
            continue
        out.append(b)
        zeros = zeros + 1 if b == 0 else 0
    return bytes(out)


class _Bits:
    """MSB-first bit reader with Exp-Golomb codes."""

    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def u(self, n: int) -> int:
        v = 0
        for _ in range(n):
            v = (v << 1) | ((self.data[self.pos >> 3] >> (7 - (self.pos & 7))) & 1)
            self.pos += 1
        return v

    def ue(self) -> int:
        zeros = 0
        while self.u(1) == 0:
            zeros += 1
            if zeros > 31:
                raise ValueError("malformed Exp-Golomb code")
        return (1 << zeros) - 1 + self.u(zeros)


def _decode(path, decoded: Iterator, max_frames: int | None, max_side: int, expected: int) -> np.ndarray:
    """Frames one by one into one (N, H, W, 3) array, each checked before it is converted; stop at the first frame
    past `max_frames`. `expected` (the header's frame count, which can lie) only sizes the first allocation,
    within `max_frames` (or `FIRST_ALLOCATION` frames without it); more frames grow it, fewer are cut off."""
    out: np.ndarray | None = None
    planar: _Planar | None = None
    n = 0
    for frame in decoded:
        if max_frames is not None and n == max_frames:
            raise _too_many(path, f"more than {max_frames} frames (decoding stopped there)", max_frames)
        _check_side(path, frame.width, frame.height, max_side)
        if out is None:
            first = min(expected, max_frames if max_frames is not None else FIRST_ALLOCATION)
            out = np.empty((max(first, 1), frame.height, frame.width, 3), np.uint8)
            planar = _Planar(frame.height, frame.width)
        elif out.shape[1:3] != (frame.height, frame.width):
            raise VideoError(f"{path}: the resolution changes mid-video ({out.shape[2]}×{out.shape[1]} "
                             f"then {frame.width}×{frame.height}); export every frame at one resolution")
        if n == len(out):  # more frames than the header said: double, within max_frames
            grow = n if max_frames is None else min(n, max_frames - n)
            out = np.concatenate([out, np.empty((grow, *out.shape[1:]), np.uint8)])
        if frame.format.name == "gbrp":
            planar.add(frame, out, n)
        else:
            planar.flush(out)
            out[n] = frame.to_ndarray(format="rgb24")
        n += 1
    if out is None:
        return np.zeros((0, 0, 0, 3), np.uint8)
    planar.flush(out)
    return out[:n]


class _Planar:
    """Planar RGB frames (libx264rgb's `gbrp`, what `write_video` writes) interleaved into the output by
    `cv2.merge`: the same bytes as libswscale's conversion. Frames of at most `CHUNK_MAX_PIXELS` are gathered
    `MERGE_CHUNK` at a time and merged by one call, which saves OpenCV's per-call overhead (7 % of decoding at 128²);
    larger ones are merged one by one, straight from the decoder's planes, where the extra copy would cost more
    (320×240: 5 % slower gathered)."""

    def __init__(self, height: int, width: int):
        import cv2

        self.merge, self.height, self.width = cv2.merge, height, width
        gather = height * width <= CHUNK_MAX_PIXELS
        self.planes = np.empty((3, MERGE_CHUNK, height, width), np.uint8) if gather else None  # g, b, r
        self.start, self.count = 0, 0

    def add(self, frame, out: np.ndarray, index: int) -> None:
        """Frame `frame` as output frame `index` (frames arrive in order)."""
        g, b, r = (np.frombuffer(p, np.uint8).reshape(self.height, p.line_size)[:, :self.width]
                   for p in frame.planes)
        if self.planes is None:
            self.merge([r, g, b], dst=out[index])
            return
        if self.count == 0:
            self.start = index
        gathered = self.planes[:, self.count]
        gathered[0], gathered[1], gathered[2] = g, b, r
        self.count += 1
        if self.count == MERGE_CHUNK:
            self.flush(out)

    def flush(self, out: np.ndarray) -> None:
        """Interleave the gathered frames into `out` as RGB."""
        k = self.count
        if k == 0:
            return
        rows = k * self.height
        g, b, r = (self.planes[i, :k].reshape(rows, self.width) for i in range(3))
        self.merge([r, g, b], dst=out[self.start:self.start + k].reshape(rows, self.width, 3))
        self.count = 0


def write_video(path, frames: np.ndarray, fps: float) -> None:
    """Write RGB uint8 frames (N, H, W, 3) as lossless RGB h264 (libx264rgb, crf 0) mp4: decoding gives back
    exactly these frames, so a baseline or a model run through `wsp generate` is scored on what it produced.
    `tune fastdecode` (no CABAC) decodes in half the time for ≈ 15 % more bytes (docs/performance.md)."""
    import av

    frames = np.asarray(frames, dtype=np.uint8)
    if frames.ndim != 4 or frames.shape[-1] != 3 or len(frames) == 0:
        raise VideoError(f"{path}: expected frames of shape (N, H, W, 3), got {frames.shape}")
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264rgb", rate=int(round(fps)))
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "rgb24"
        stream.options = {"crf": "0", "preset": "medium", "tune": "fastdecode", "threads": "1"}
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
