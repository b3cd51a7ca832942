"""RulesJudge on hand-built synthetic clips whose answer is obvious (no release, no simulator).

Every clip is 12 frames of 128×128 RGB, like the T5 references: a saturated orange, grain-textured "table"; a
saturated blue object; and a light-grey "robot" — a thick arm from its base at the top of the image (where the
judge assumes the robot stands) to a hand that approaches the object from elsewhere, as a real arm does. Paths
are given per frame in 128-px units; `object_px` is the object's frame-0 centre in the 256×256 scoring frame.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from wsp_eval.backends.judge import PRIMITIVES, Verdict, score_verdict
from wsp_eval.backends.judge_rules import RulesJudge

T = 12
BLUE = (40, 90, 220)
ROBOT = (215, 215, 220)
OBJ = (64.0, 70.0)  # the object's frame-0 centre: below the robot base at (64, 0)


def _table() -> np.ndarray:
    rng = np.random.default_rng(0)
    rows = rng.normal(0, 12, size=(128, 1, 1))  # horizontal wood-like grain
    base = np.array([200.0, 110.0, 60.0])
    return np.clip(base + rows * np.array([1.0, 0.6, 0.4]), 0, 255).astype(np.uint8).repeat(128, axis=1)


TABLE = _table()


def _px256(p: tuple[float, float]) -> tuple[float, float]:
    return tuple((c + 0.5) * 2 - 0.5 for c in p)


def clip(obj_path, hand_path, *, shape="square", size=6, base=(64, 0), obj_angle=None, tall_path=None):
    """Draw the clip. `obj_path`/`hand_path`: T (x, y) points; the hand is a 14×6 grey block centred there, the
    arm a thick grey line from `base` to it, drawn over the object (the robot occludes what it covers).
    `shape`: square | ball. `obj_angle`: per-frame rotation (deg) of a 10×4 bar instead; `tall_path`: per-frame
    (w, h) of an upright or lying box instead."""
    frames = []
    for t in range(T):
        f = TABLE.copy()
        x, y = obj_path[t]
        if obj_angle is not None:
            box = cv2.boxPoints(((x, y), (10, 4), obj_angle[t])).round().astype(np.int32)
            cv2.fillPoly(f, [box], BLUE)
        elif tall_path is not None:
            w, h = tall_path[t]
            cv2.rectangle(f, (round(x - w / 2), round(y - h / 2)), (round(x + w / 2), round(y + h / 2)), BLUE, -1)
        elif shape == "ball":
            cv2.circle(f, (round(x), round(y)), size // 2 + 1, BLUE, -1)
        else:
            h = size // 2
            cv2.rectangle(f, (round(x) - h, round(y) - h), (round(x) + h - 1, round(y) + h - 1), BLUE, -1)
        hx, hy = hand_path[t]
        cv2.line(f, base, (round(hx), round(hy) - 6), ROBOT, 9)
        cv2.rectangle(f, (round(hx) - 7, round(hy) - 6), (round(hx) + 7, round(hy)), ROBOT, -1)
        cv2.circle(f, (round(hx), round(hy) - 12), 3, (30, 30, 30), -1)  # a dark joint: texture on the arm
        frames.append(f)
    return np.stack(frames)


def approach(target, n=5, start=(25.0, 30.0)):
    """The hand's first `n` frames: from `start` straight to `target`."""
    return [(start[0] + (target[0] - start[0]) * i / (n - 1), start[1] + (target[1] - start[1]) * i / (n - 1))
            for i in range(n)]


def judge(frames) -> Verdict:
    return RulesJudge().judge(frames, _px256(OBJ))


def above(p, gap=1.0):
    """Where the hand rests on top of (on the robot side of) a 6-px object at `p`."""
    return (p[0], p[1] - 3 - gap)


def below(p, gap=1.0):
    return (p[0], p[1] + 3 + gap + 6)


def test_push_away_from_the_robot():
    # the hand comes down onto the robot side of the cube and slides it 12 px down the image (away from the
    # base at the top) over four frames; the cube then rests, the hand lifts a little: a push
    obj = [OBJ] * 5 + [(64, 70 + 3 * k) for k in range(1, 5)] + [(64, 82)] * 3
    hand = approach(above(OBJ)) + [above(p) for p in obj[5:9]] + [(64, 74), (64, 72), (64, 70)]
    v = judge(clip(obj, hand))
    assert v.label == "push" and v.agent_ok and v.object_ok, v
    assert score_verdict(v, "push") == 100.0


def test_pull_toward_the_robot():
    # the same, from the far side: the cube slides 12 px up the image, toward the robot base (the arm is drawn
    # from the top right so that it does not cover the cube; the judge still takes the robot to be at the top)
    obj = [OBJ] * 5 + [(64, 70 - 3 * k) for k in range(1, 5)] + [(64, 58)] * 3
    hand = approach(below(OBJ), start=(100, 100)) + [below(p) for p in obj[5:9]] + [(70, 72), (76, 80), (82, 88)]
    v = RulesJudge().judge(clip(obj, hand, base=(120, 0)), _px256(OBJ))
    assert v.label == "pull" and v.agent_ok and v.object_ok, v


def test_drag_sideways():
    # the hand sits on the cube and carries it 12 px to the right (perpendicular to the robot direction)
    obj = [OBJ] * 5 + [(64 + 3 * k, 70) for k in range(1, 5)] + [(76, 70)] * 3
    hand = approach(above(OBJ)) + [above(p) for p in obj[5:9]] + [(76, 62), (76, 58), (76, 54)]
    v = judge(clip(obj, hand))
    assert v.label == "drag" and v.agent_ok and v.object_ok, v


def test_shake_back_and_forth_in_place():
    # grasped, the cube swings ±5 px sideways twice (four reversals) and is set down where it started
    swing = [0, 5, -5, 5, -5, 0]
    obj = [OBJ] * 4 + [(64 + s, 70) for s in swing] + [OBJ] * 2
    hand = approach(above(OBJ), n=4) + [above(p) for p in obj[4:10]] + [(64, 60), (64, 56)]
    v = judge(clip(obj, hand))
    assert v.label == "shake" and v.agent_ok and v.object_ok, v


def test_drop_rises_then_falls_back():
    # grasped, the cube rises 6 px up the image (lifted), then falls back to its spot; the hand stays up
    obj = [OBJ] * 5 + [(64, 67), (64, 64), (64, 64)] + [OBJ] * 4
    hand = approach(above(OBJ)) + [above(p) for p in obj[5:8]] + [(64, 60)] * 4
    v = judge(clip(obj, hand))
    assert v.label == "drop" and v.agent_ok and v.object_ok, v


def test_tap_the_ball_rolls_on_by_itself():
    # the hand touches the ball once and retreats at once; the ball keeps rolling down the image, 5 px per
    # frame, to the very last frame
    obj = [OBJ] * 5 + [(64, 70 + 5 * k) for k in range(1, 8)]
    hand = approach(above(OBJ, gap=1.5)) + [(64, 60 - 4 * k) for k in range(1, 8)]
    v = judge(clip(obj, hand, shape="ball", size=8))
    assert v.label == "tap" and v.agent_ok and v.object_ok, v


def test_knock_over_a_tall_box():
    # an upright 4×12 box is struck and, within one frame, lies 12×4 a little further from the robot; the hand
    # draws back up and away
    obj = [OBJ] * 6 + [(64, 78)] * 6
    tall = [(4, 12)] * 6 + [(12, 4)] * 6
    hand = approach((64, 62), n=6) + [(64, 50), (60, 40), (56, 34), (50, 30), (46, 28), (44, 26)]
    v = judge(clip(obj, hand, tall_path=tall))
    assert v.label == "knock-over" and v.agent_ok and v.object_ok, v


def test_rotate_in_place():
    # a 10×4 bar is grasped and turned by 40° where it lies; the hand then lifts off
    obj = [OBJ] * T
    angle = [0] * 6 + [20] + [40] * 5
    hand = approach(above(OBJ, gap=2)) + [above(OBJ, gap=2)] * 3 + [(64, 60), (64, 52), (64, 46), (64, 42)]
    v = judge(clip(obj, hand, obj_angle=angle))
    assert v.label == "rotate" and v.agent_ok and v.object_ok, v


@pytest.mark.parametrize("intended", PRIMITIVES)
def test_static_video_scores_zero(intended):
    # frame 0 of the push clip repeated: nothing moves, so whatever the label, the score is 0
    obj = [OBJ] * T
    frames = np.repeat(clip(obj, approach(above(OBJ)) + [above(OBJ)] * 7)[:1], T, axis=0)
    v = judge(frames)
    assert not (v.agent_ok and v.object_ok)
    assert score_verdict(v, intended) == 0.0


def test_object_vanishing_is_not_a_primitive():
    # the robot approaches and the object simply disappears (a generated clip losing it): no primitive shows
    frames = clip([OBJ] * T, approach(above(OBJ)) + [above(OBJ)] * 7)
    frames[3:, 60:80, 54:74] = TABLE[60:80, 54:74]
    v = judge(frames)
    assert not (v.agent_ok and v.object_ok), v


WEIRD = {
    "tiny": np.zeros((1, 2, 2, 3), np.uint8),
    "one_pixel_frames": np.full((12, 1, 1, 3), 128, np.uint8),
    "constant": np.zeros((12, 64, 64, 3), np.uint8),
    "noise": np.random.default_rng(1).integers(0, 256, (12, 96, 80, 3), dtype=np.uint8),
    "grey_float_with_nan": np.where(np.random.default_rng(2).random((12, 50, 50)) < 0.1, np.nan, 0.5),
    "rgba_big": np.random.default_rng(3).integers(0, 256, (12, 300, 200, 4), dtype=np.uint8),
    "single_frame": np.repeat(TABLE[None], 1, axis=0),
    "wrong_rank": np.zeros((12, 64), np.uint8),
    "empty": np.zeros((0, 64, 64, 3), np.uint8),
    "object_list": [[1, 2], [3]],
}


@pytest.mark.parametrize("name", sorted(WEIRD))
def test_weird_videos_never_raise(name):
    for px in [(128.0, 140.0), (-50.0, 900.0), (math.nan, 3.0)]:
        v = RulesJudge().judge(WEIRD[name], px)
        assert isinstance(v, Verdict)
        assert v.label is None or not (v.agent_ok and v.object_ok), (name, px, v)


def test_deterministic():
    obj = [OBJ] * 5 + [(64, 70 + 3 * k) for k in range(1, 5)] + [(64, 82)] * 3
    hand = approach(above(OBJ)) + [above(p) for p in obj[5:9]] + [(64, 74), (64, 72), (64, 70)]
    frames = clip(obj, hand)
    a, b = judge(frames), judge(frames.copy())
    assert (a.label, a.agent_ok, a.object_ok) == (b.label, b.agent_ok, b.object_ok)
    assert a.evidence == b.evidence
    assert all(isinstance(x, (float, str)) for x in a.evidence.values())


def test_judge_identity():
    j = RulesJudge()
    assert j.name == "rules" and isinstance(j.version, str) and j.version
