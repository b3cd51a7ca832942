"""Hostile uploads, on real files damaged from a real oracle submission of the tiny T1 release: every one gets a
per-file problem that names the file, what was found and the fix, decoding stays bounded (refused from the
stream header, or stopped at the first frame past the horizon), the other files still validate, and `wsp score`
scores every other instance, bit-identically to the untouched oracle, and resumes from its cache."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pyarrow.parquet as pq
import pytest

from wsp_eval.baselines import write_baseline
from wsp_eval.score import CACHE, ScoreError, score_submission
from wsp_eval.submission import SUBMISSION_JSON, validate
from wsp_eval.video import CHUNK_MAX_PIXELS, MERGE_CHUNK, VideoError, read_video, write_video

CONFIG = "t1_maniskill"


@pytest.fixture(scope="module")
def oracle(t1_release, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("hostile") / "oracle"
    assert write_baseline("oracle", t1_release, out, seeds=(0,)) > 0
    return out


@pytest.fixture(scope="module")
def oracle_report(oracle, t1_release, tmp_path_factory) -> dict:
    return score_submission(oracle, t1_release, tmp_path_factory.mktemp("oracle-report"), progress=False)


@pytest.fixture(scope="module")
def rows(t1_release) -> list[dict]:
    return pq.read_table(t1_release / CONFIG / "instances.parquet").to_pylist()


@pytest.fixture
def sub(oracle, tmp_path) -> Path:
    """A fresh copy of the valid oracle submission, to damage."""
    return Path(shutil.copytree(oracle, tmp_path / "sub"))


def rel(i: int) -> str:
    return f"{CONFIG}/episode_{i:06d}/seed0.mp4"


def horizon(rows: list[dict], i: int) -> int:
    return next(n for r in rows for e, n in zip(r["episode_ids"], r["num_frames"]) if e == f"episode_{i:06d}")


def by_file(sub: Path, release: Path) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for p in validate(sub, release):
        out.setdefault(p.path, []).append(p.message)
    return out


def encode(path: Path, frames: np.ndarray, fps=20, fmt: str | None = None, options: dict | None = None,
           pix_fmt: str = "yuv444p", quality: dict | None = None, codec: str = "libx264") -> None:
    """A real h264 file, lossless 4:4:4 unless told otherwise (the accepted encoding; `pix_fmt` and `quality`
    make a lossy one; `codec` "libx264rgb" with `pix_fmt` "rgb24" makes planar RGB, as `write_video` does),
    ultrafast: quick to write at any size or length, like a model's export."""
    with av.open(str(path), "w", format=fmt, options=options or {}) as container:
        stream = container.add_stream(codec, rate=fps)
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], pix_fmt
        stream.options = {"preset": "ultrafast", **(quality or {"qp": "0"})}
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def moving(n: int, height: int, width: int) -> np.ndarray:
    frames = np.zeros((n, height, width, 3), np.uint8)
    frames[..., 0] = (np.arange(n) * 3 % 256)[:, None, None]
    return frames


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "wsp_eval.cli", *args], capture_output=True, timeout=300)


def test_oversize_resolution_is_refused_from_the_header(sub, t1_release, rows):
    encode(sub / rel(0), moving(horizon(rows, 0), 1080, 1920))
    assert by_file(sub, t1_release) == {rel(0): [
        "1920×1080 pixels; at most 512 per side is accepted (references are at most 320×240): export at the "
        "reference's resolution (the first frame's size)"]}
    with pytest.raises(VideoError, match="1920×1080 pixels"):
        read_video(sub / rel(0))  # no horizon given: the resolution cap still holds


def test_a_header_that_lies_about_the_resolution(sub, t1_release, tmp_path):
    """Raw h264 streams joined end to end: the header describes the first; every decoded frame is checked."""
    small, wide, other = tmp_path / "small.h264", tmp_path / "wide.h264", tmp_path / "other.h264"
    encode(small, moving(10, 128, 128), fmt="h264")
    encode(wide, moving(3, 1080, 1920), fmt="h264")
    encode(other, moving(10, 32, 48), fmt="h264")
    (sub / rel(0)).write_bytes(small.read_bytes() + wide.read_bytes())
    (sub / rel(3)).write_bytes(small.read_bytes() + other.read_bytes())
    with av.open(str(sub / rel(0))) as container:
        assert (container.streams.video[0].codec_context.width, container.streams.video[0].frames) == (128, 0)
    problems = by_file(sub, t1_release)
    assert set(problems) == {rel(0), rel(3)}
    assert problems[rel(0)][0].startswith("1920×1080 pixels; at most 512 per side is accepted")
    assert problems[rel(3)] == ["the resolution changes mid-video (128×128 then 48×32); export every frame at one "
                                "resolution"]


def test_far_too_many_frames_stop_decoding(sub, t1_release, rows):
    many = np.random.default_rng(0).integers(0, 256, (3000, 16, 16, 3), dtype=np.uint8)
    encode(sub / rel(3), many)                   # mp4: the header says 3000
    encode(sub / rel(6), many, fmt="h264")       # a raw h264 stream named .mp4: the header says nothing (0)
    with av.open(str(sub / rel(6))) as container:
        assert container.streams.video[0].frames == 0
    assert by_file(sub, t1_release) == {
        rel(3): [f"3000 frames (stream header); the reference horizon is {horizon(rows, 3)}: export exactly "
                 f"{horizon(rows, 3)} frames (frame j at j/fps)"],
        rel(6): [f"more than {horizon(rows, 6)} frames (decoding stopped there); the reference horizon is "
                 f"{horizon(rows, 6)}: export exactly {horizon(rows, 6)} frames (frame j at j/fps)"]}


def test_a_header_without_a_frame_count_decodes_every_frame(tmp_path):
    """Frames are decoded into one array sized by the header's count; a raw stream's header says 0, so the array
    grows from one frame (doubling, within the horizon): the same frames as the same stream in an mp4."""
    frames = np.random.default_rng(1).integers(0, 256, (37, 24, 40, 3), dtype=np.uint8)
    encode(tmp_path / "a.mp4", frames)
    encode(tmp_path / "a.h264", frames, fmt="h264")
    counted, _ = read_video(tmp_path / "a.mp4")
    for grown in (read_video(tmp_path / "a.h264")[0], read_video(tmp_path / "a.h264", max_frames=37)[0]):
        assert grown.shape == counted.shape == (37, 24, 40, 3)
        np.testing.assert_array_equal(grown, counted)
    with pytest.raises(VideoError, match="more than 36 frames"):
        read_video(tmp_path / "a.h264", max_frames=36)


@pytest.mark.parametrize("n, height, width", [(1, 24, 40), (MERGE_CHUNK, 24, 40), (2 * MERGE_CHUNK + 5, 24, 40),
                                              (MERGE_CHUNK + 3, 194, 192)])
def test_planar_rgb_comes_back_exactly(tmp_path, n, height, width):
    """`write_video`'s planar RGB (gbrp) is interleaved `MERGE_CHUNK` frames at a time (one by one above
    `CHUNK_MAX_PIXELS`): every frame comes back exactly, at a chunk's edges, and when the array grows under a
    half-filled chunk (a raw stream: no count)."""
    assert (194 * 192 > CHUNK_MAX_PIXELS) and 24 * 40 <= CHUNK_MAX_PIXELS
    frames = np.random.default_rng(n).integers(0, 256, (n, height, width, 3), dtype=np.uint8)
    write_video(tmp_path / "a.mp4", frames, 20)
    encode(tmp_path / "a.h264", frames, fmt="h264", codec="libx264rgb", pix_fmt="rgb24", quality={"crf": "0"})
    for name in ("a.mp4", "a.h264"):
        with av.open(str(tmp_path / name)) as container:  # what the planar path reads
            assert next(container.decode(video=0)).format.name == "gbrp"
        np.testing.assert_array_equal(read_video(tmp_path / name)[0], frames)


def test_a_file_larger_than_any_allowed_video_is_refused_unopened(sub, t1_release, rows):
    n = horizon(rows, 9)
    with open(sub / rel(9), "wb") as f:
        f.truncate(n * 2 * 512 * 512 * 3 + (2 << 20))  # sparse: no disk or time spent
    problems = by_file(sub, t1_release)
    assert list(problems) == [rel(9)]
    (message,) = problems[rel(9)]
    assert message.startswith(f"{(sub / rel(9)).stat().st_size / 1e6:.1f} MB, more than {n} frames of at most "
                              "512×512 take even lossless")


def test_truncated_files(sub, t1_release):
    data = (sub / rel(1)).read_bytes()
    (sub / rel(1)).write_bytes(data[: len(data) // 3])  # the index (moov, at the end) is cut off
    frames, _ = read_video(sub / rel(4))
    encode(sub / rel(4), frames, options={"movflags": "faststart"})  # index first: the frame data is cut
    data = (sub / rel(4)).read_bytes()
    (sub / rel(4)).write_bytes(data[: len(data) // 2])
    problems = by_file(sub, t1_release)
    assert set(problems) == {rel(1), rel(4)}
    for r in (rel(1), rel(4)):
        (message,) = problems[r]
        assert message.startswith("unreadable video (") and "re-export it as an h264 mp4" in message


def test_files_that_are_not_videos(sub, t1_release):
    """Text, random bytes and JSON named .mp4 are unreadable; a FIFO or a folder in a video's place is missing."""
    (sub / rel(2)).write_text("this is not a video\n" * 100)
    (sub / rel(5)).write_bytes(np.random.default_rng(1).integers(0, 256, 1 << 20, dtype=np.uint8).tobytes())
    (sub / rel(8)).write_text(json.dumps({"frames": [[0, 0, 0]]}))
    for i in (0, 3):
        (sub / rel(i)).unlink()
    os.mkfifo(sub / rel(0))  # opened, it would block forever
    (sub / rel(3)).mkdir()
    problems = by_file(sub, t1_release)
    assert set(problems) == {rel(0), rel(2), rel(3), rel(5), rel(8)}
    assert problems[rel(0)] == problems[rel(3)] == ["missing"]  # a submission holds plain files
    assert all(problems[rel(i)][0].startswith("unreadable video (") and len(problems[rel(i)]) == 1 for i in (2, 5, 8))


def test_links_pointing_outside_are_named_and_never_followed(sub, t1_release, tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(sub / rel(8), outside / "seed0.mp4")
    (sub / rel(8)).unlink()
    os.symlink(outside / "seed0.mp4", sub / rel(8))         # a video linked from outside
    os.symlink(outside, sub / CONFIG / "escape")            # a folder linked from outside
    os.symlink("..", sub / CONFIG / "loop")                 # a loop
    problems = by_file(sub, t1_release)
    assert problems == {
        rel(8): [f"is a link (outside the submission: {outside / 'seed0.mp4'}); submit plain files", "missing"],
        f"{CONFIG}/escape": [f"is a link (outside the submission: {outside}); submit plain files"],
        f"{CONFIG}/loop": [f"is a link (inside it: {sub.resolve()}); submit plain files"]}
    with pytest.raises(ScoreError, match="is a link"):  # links refuse the whole submission before scoring
        score_submission(sub, t1_release, tmp_path / "report", progress=False, allow_missing=True)


def test_odd_names_and_paths(sub, t1_release, tmp_path):
    odd = ["episode_000000/seed0 copy.mp4", "épisode ü/seed0.mp4", "..seed0.mp4", "episode_000001/..mp4",
           "new\nline.mp4"]
    (sub / CONFIG / "épisode ü").mkdir()
    for name in odd:
        (sub / CONFIG / name).write_bytes(b"x")
    (sub / os.fsdecode(b"\xff\xfe not utf-8.mp4")).write_bytes(b"x")
    expected = {f"{CONFIG}/{name}": ["unexpected file"] for name in odd} | {
        "\\xff\\xfe not utf-8.mp4": ["unexpected file"]}
    assert by_file(sub, t1_release) == expected
    r = cli("validate", str(sub), "--release", str(t1_release))
    out = r.stdout.decode("utf-8")  # printable whatever bytes a name holds
    assert r.returncode == 1 and b"Traceback" not in r.stderr and "\\xff\\xfe not utf-8.mp4: unexpected file" in out

    meta = json.loads((sub / SUBMISSION_JSON).read_text())
    for configs in (["../" + CONFIG], [f"{CONFIG}/../{CONFIG}"], ["/etc"]):
        (sub / SUBMISSION_JSON).write_text(json.dumps({**meta, "configs": configs}))
        assert by_file(sub, t1_release) == {SUBMISSION_JSON: [f"configs not in the release: {configs[0]}"]}


MALFORMED = {
    "not JSON": (b"{model: m}", "not valid JSON (Expecting property name"),
    "cut short": (b'{"model": "m", "seeds": [0', "not valid JSON (Expecting"),
    "nested too deep": (b"[" * 200_000 + b"]" * 200_000, "not valid JSON (nested too deep)"),
    "not UTF-8": (b"\xff\xfe{}", "not valid JSON ("),
    "a list": (b"[0, 1]", "must be a JSON object"),
    "seeds as booleans": (b'{"model": "m", "benchmark_version": "VERSION", "seeds": [true]}',
                          "'seeds' must be a non-empty list of distinct non-negative integers"),
    "wrong types": (b'{"model": 3, "benchmark_version": "VERSION", "seeds": "0"}', "'model' missing or not a str"),
}


@pytest.mark.parametrize("case", MALFORMED)
def test_malformed_submission_json(sub, t1_release, tmp_path, case):
    content, message = MALFORMED[case]
    version = json.loads((sub / SUBMISSION_JSON).read_text())["benchmark_version"]
    (sub / SUBMISSION_JSON).write_bytes(content.replace(b"VERSION", version.encode()))
    problems = validate(sub, t1_release)
    assert problems and all(p.path == SUBMISSION_JSON for p in problems)
    assert problems[0].message.startswith(message), problems
    with pytest.raises(ScoreError, match="the submission is not scorable"):
        score_submission(sub, t1_release, tmp_path / "report", progress=False)


def test_huge_submission_json_is_refused_by_size_before_parsing(sub, t1_release):
    with open(sub / SUBMISSION_JSON, "wb") as f:  # 50 MB that is not even JSON: read, it would say so
        f.write(b'{"model": "' + b"x" * 50_000_000)
    assert [str(p) for p in validate(sub, t1_release)] == [
        "submission.json: 50.0 MB; at most 1024 KiB is read (it holds model, benchmark_version, seeds and a few "
        "optional fields)"]
    r = cli("validate", str(sub), "--release", str(t1_release))
    assert r.returncode == 1 and b"Traceback" not in r.stderr and b"1 problem(s)" in r.stdout


def test_wrong_frame_rates(sub, t1_release):
    """fps outside 1–240 is a problem; another plausible fps is the model's timebase (frame j at j/fps, spec §4.1)
    and is accepted."""
    for i, fps in ((0, 1000), (3, Fraction(1, 2)), (6, 10)):
        frames, _ = read_video(sub / rel(i))
        encode(sub / rel(i), frames, fps=fps)
    assert by_file(sub, t1_release) == {rel(0): ["fps missing or absurd (1000.0); expected 20"],
                                        rel(3): ["fps missing or absurd (0.5); expected 20"]}
    assert read_video(sub / rel(6))[1] == 10.0


def test_another_resolution_than_the_reference_is_refused(sub, t1_release, oracle_report, tmp_path):
    """A video resampled from the reference's 128×128 (here 2× up, losslessly) is refused by validate and score
    (resampling alone costs the oracle up to 5 points, docs/submission.md); with --accept-lossy it is scored,
    and T1, which compares an instance's videos pixel by pixel, then names the one unlike the others and scores
    that seed 0 instead of failing."""
    frames, _ = read_video(sub / rel(1))
    encode(sub / rel(1), np.repeat(np.repeat(frames, 2, axis=1), 2, axis=2))
    refused = "256×256 pixels; the references of t1_maniskill are 128×128: export at the reference's resolution " \
              "(a resampled oracle loses up to 5 points of T1-T3, docs/submission.md), or score it anyway with " \
              "`wsp score --accept-lossy`"
    assert by_file(sub, t1_release) == {rel(1): [refused]}
    report = score_submission(sub, t1_release, tmp_path / "refused", progress=False, allow_missing=True)
    assert report["problems"] == [f"{rel(1)}: {refused}"]
    assert report["encoding_check"] == "lossless at the reference resolution only"
    unlike = "256×256 pixels, unlike the 128×128 of the other videos of its instance; export every video of an " \
             "instance at one resolution"
    report = score_submission(sub, t1_release, tmp_path / "accepted", progress=False, allow_missing=True,
                              accept_lossy=True)
    assert report["problems"] == [f"{rel(1)}: {unlike}"]
    assert report["encoding_check"] == "off (lossy or resampled videos scored)"
    assert [r["score"] for r in report["instances"]] == [0.0] + [r["score"] for r in oracle_report["instances"][1:]]


def test_score_keeps_every_other_instance_and_resumes(sub, t1_release, oracle_report, tmp_path):
    """Three instances each hold one hostile file; the fourth is scored bit-identically to the oracle's, a run
    without --allow-missing stops at the end with every file named and its records cached, and a re-run
    (allowed, or after an interruption) continues from the cache."""
    encode(sub / rel(0), moving(3, 1080, 1920))                                          # oversize
    (sub / rel(4)).write_text("not a video")                                             # not a video
    encode(sub / rel(7), np.zeros((3000, 16, 16, 3), np.uint8) + 7)                      # far too many frames
    out = tmp_path / "report"
    with pytest.raises(ScoreError, match="3 unusable video") as e:
        score_submission(sub, t1_release, out, progress=False)
    assert all(rel(i) in str(e.value) for i in (0, 4, 7)) and "--allow-missing" in str(e.value)
    assert len((out / CACHE).read_text().splitlines()) == 4

    report = score_submission(sub, t1_release, out, progress=False, allow_missing=True)
    assert report["timing"]["instances"] == 0  # every instance came from the cache
    scores = [r["score"] for r in report["instances"]]
    assert scores == [0.0, 0.0, 0.0, oracle_report["instances"][3]["score"]]
    assert [p.split(":")[0] for p in report["problems"]] == [rel(0), rel(4), rel(7)]

    lines = (out / CACHE).read_text().splitlines()
    (out / CACHE).write_text(lines[0] + "\n" + lines[1][: len(lines[1]) // 2])  # killed mid-write
    again = score_submission(sub, t1_release, out, progress=False, allow_missing=True)
    assert again["timing"]["instances"] == 3 and [r["score"] for r in again["instances"]] == scores
    assert again["platforms"] == report["platforms"]
    assert score_submission(sub, t1_release, out, progress=False, allow_missing=True)["timing"]["instances"] == 0


# -- encodings (spec §4.7; docs/submission.md) ----------------------------------------------------------------
LOSSY = {  # name → (pix_fmt, quality, the problem's first words)
    "4:2:0 crf 23": ("yuv420p", {"crf": "23"}, "chroma-subsampled h264 (4:2:0, pix_fmt yuv420p)"),
    "4:2:0 qp 0": ("yuv420p", {"qp": "0"}, "chroma-subsampled h264 (4:2:0, pix_fmt yuv420p)"),
    "4:4:4 crf 18": ("yuv444p", {"crf": "18"}, "lossy h264 (pix_fmt yuv444p, quantised: crf or qp above 0)"),
}


@pytest.mark.parametrize("name", LOSSY)
def test_lossy_or_chroma_subsampled_videos_are_refused_with_the_fix(sub, t1_release, name):
    pix_fmt, quality, problem = LOSSY[name]
    frames, fps = read_video(sub / rel(2))
    encode(sub / rel(2), frames, fps=int(fps), pix_fmt=pix_fmt, quality=quality)
    (message,) = by_file(sub, t1_release)[rel(2)]
    assert message.startswith(problem) and "; save the model's frames losslessly: `wsp generate`" in message
    assert "libx264rgb -crf 0" in message
    frames_back, _ = read_video(sub / rel(2))  # without the contract's check it decodes: only the contract refuses
    assert frames_back.shape == frames.shape


@pytest.mark.parametrize("codec", ["png", "mpeg4"])
def test_other_codecs(sub, t1_release, codec):
    """PNG in mp4 is lossless and accepted; any other codec is refused by name."""
    frames, fps = read_video(sub / rel(5))
    with av.open(str(sub / rel(5)), "w") as container:
        stream = container.add_stream(codec, rate=int(fps))
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "rgb24" if codec == "png" else "yuv420p"
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    if codec == "png":
        assert validate(sub, t1_release) == []
        assert np.array_equal(read_video(sub / rel(5))[0], frames)
    else:
        assert by_file(sub, t1_release)[rel(5)][0].startswith("mpeg4 video is not an accepted encoding")


def test_lossless_444_passes_and_lossy_scores_only_when_accepted(sub, t1_release, oracle_report, tmp_path):
    """Lossless 4:4:4 YUV (colour conversion rounding only) keeps the oracle's score; a lossy video stops
    `wsp score` unless --accept-lossy, and then the report says the check was off."""
    for i in (0, 1, 2):
        frames, fps = read_video(sub / rel(i))
        encode(sub / rel(i), frames, fps=int(fps))
    assert validate(sub, t1_release) == []
    report = score_submission(sub, t1_release, tmp_path / "lossless", progress=False)
    # tolerance: 4:4:4 YUV rounds each colour by at most ~1 level; measured change 0.0 points (docs/submission.md)
    assert abs(report["instances"][0]["score"] - oracle_report["instances"][0]["score"]) < 2.0
    frames, fps = read_video(sub / rel(1))
    encode(sub / rel(1), frames, fps=int(fps), pix_fmt="yuv420p", quality={"crf": "23"})
    with pytest.raises(ScoreError, match="chroma-subsampled"):
        score_submission(sub, t1_release, tmp_path / "refused", progress=False)
    report = score_submission(sub, t1_release, tmp_path / "accepted", progress=False, accept_lossy=True)
    assert report["encoding_check"].startswith("off") and report["problems"] == []
    md = (tmp_path / "accepted" / "report.md").read_text()
    assert "not comparable with lossless submissions" in md


def test_the_h264_parameter_set_parser_on_damaged_input():
    from wsp_eval.video import h264_sps

    assert h264_sps(b"") is None
    assert h264_sps(b"\x01\x64\x00\x1f\xff\xe1\x00\x02\x67") is None  # a truncated SPS
    assert h264_sps(b"\x00\x00\x00\x01\x68\xee") is None  # Annex B without an SPS
