"""T4's presence rule on synthetic clips whose object mask is known exactly: a still square stays present when it
is drawn noisy, lightly blurred or a pixel off (given the tracked shift); it is absent when it fades out, is
erased, or smears away; frames where the robot hides it or it does not stand out do not count."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wsp_eval import object_presence as op

N, H, W, FPS = 30, 128, 128, 10.0
SQUARE = (slice(60, 68), slice(60, 68))  # 8 px: a LIBERO-sized object at 128²


def scene(colour=(200, 40, 40)) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    table = (np.full((H, W, 3), (120, 110, 90), np.float64) + rng.normal(0, 3, (H, W, 3))).clip(0, 255)
    frames = np.repeat(table.astype(np.uint8)[None], N, axis=0)
    obj = np.zeros((N, H, W), bool)
    obj[:, SQUARE[0], SQUARE[1]] = True
    frames[obj] = colour
    return frames, obj


def reference(frames, obj, robot=None):
    robot = np.zeros_like(obj) if robot is None else robot
    return op.presence_reference(frames, obj, robot, np.zeros_like(obj), FPS)


def score(ref, video, shifts=None) -> float:
    shifts = np.zeros((N, 2)) if shifts is None else shifts
    return op.presence(op.frame_presence(video, ref, shifts), ref.window)


def test_the_reference_is_present_and_so_is_noise_or_light_blur():
    frames, obj = scene()
    ref = reference(frames, obj)
    assert score(ref, frames) == pytest.approx(1.0)
    noisy = (frames + np.random.default_rng(1).normal(0, 10, frames.shape)).clip(0, 255).astype(np.uint8)
    assert score(ref, noisy) > 0.9  # noise averages out over the object and its ring
    blurred = np.stack([cv2.GaussianBlur(f, (0, 0), 1.5) for f in frames])
    assert op.KEEP < score(ref, blurred) < 0.95  # blur lowers the contrast, far less than to the threshold


def test_an_object_that_fades_or_smears_away_is_absent():
    frames, obj = scene()
    ref = reference(frames, obj)
    plate = np.repeat(frames[:1].copy(), N, axis=0)
    plate[:, SQUARE[0], SQUARE[1]] = frames[0, 40:48, 40:48]  # the table drawn where the object stood
    fade = np.clip((np.arange(N) - N // 2) / 10.0, 0, 1)[:, None, None, None]
    faded = (frames * (1 - fade) + plate * fade).round().astype(np.uint8)
    assert score(ref, faded) < 0.1
    assert score(ref, plate) < 0.1  # erased from the start
    smeared = frames.copy()
    smeared[N // 2:] = [cv2.GaussianBlur(f, (0, 0), 6.0) for f in frames[N // 2:]]
    assert score(ref, smeared) < op.KEEP


def test_a_shifted_drawing_is_measured_where_the_tracker_puts_it():
    frames, obj = scene()
    ref = reference(frames, obj)
    moved = np.roll(frames, 6, axis=2)  # the whole picture 6 px right
    assert score(ref, moved) < op.KEEP  # measured at the reference's pixels (±1 px) the object is mostly gone
    assert score(ref, moved, np.tile([6.0, 0.0], (N, 1))) == pytest.approx(1.0)
    assert score(ref, moved, np.tile([5.4, 0.4], (N, 1))) == pytest.approx(1.0)  # rounding, then ±1 px


def test_hidden_or_plain_frames_do_not_count():
    frames, obj = scene()
    robot = np.zeros_like(obj)
    robot[: N // 2, 55:70, 55:70] = True  # the hand covers the object for the first half
    ref = reference(frames, obj, robot)
    assert [e is None for e in ref.frames] == [t < N // 2 for t in range(N)]
    erased_early = frames.copy()
    erased_early[: N // 2, SQUARE[0], SQUARE[1]] = frames[0, 40:48, 40:48]
    assert score(ref, erased_early) == pytest.approx(1.0)  # what the reference hides is not held against it
    plain, plain_obj = scene(colour=(121, 110, 90))  # the object looks like the table: nothing to compare
    assert all(e is None for e in reference(plain, plain_obj).frames)
    assert score(reference(plain, plain_obj), frames) == 1.0


def test_a_video_of_another_length_is_refused():
    frames, obj = scene()
    with pytest.raises(ValueError, match="frames against a reference"):
        op.frame_presence(frames[:-1], reference(frames, obj), np.zeros((N - 1, 2)))


def test_the_cached_record_gives_back_the_same_reference():
    """T4 keeps the presence reference in the reference-result cache as JSON: read back, it has the same pixel
    sets in the same order and v*_t to the bit, so a cached scoring equals a fresh one exactly."""
    import json

    frames, obj = scene()
    robot = np.zeros_like(obj)
    robot[: N // 3, 55:64, 55:70] = True  # part of the object hidden for a while: the sets change per frame
    ref = reference(frames, obj, robot)
    back = op.PresenceReference.from_record(json.loads(json.dumps(ref.to_record())))
    assert (back.shape, back.window) == (ref.shape, ref.window)
    assert [e is None for e in back.frames] == [e is None for e in ref.frames]
    for a, b in zip(ref.frames, back.frames):
        if a is not None:
            assert all(np.array_equal(x, y) for x, y in zip(a, b))
    smeared = frames.copy()
    smeared[N // 2:] = [cv2.GaussianBlur(f, (0, 0), 3.0) for f in frames[N // 2:]]
    for video in (frames, smeared):
        assert score(back, video) == score(ref, video)
