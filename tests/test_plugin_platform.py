"""A third-party platform plugs in through the registry and builds a real T1 config (issue #12).

`planar` is a tiny but real simulator written here, outside `wsp_data`: a 2-link planar arm (joints q0, q1, rad)
with a round hand that pushes a square box on a table, pure numpy kinematics, rendered top-down at 128×128 with
OpenCV (anti-aliased, sub-pixel: a 0.0025 rad joint change moves pixels) and with an exact robot label mask
(1 arm links, 2 hand). Its one task, PushBox, is solved by a scripted expert (inverse kinematics along a
straight hand path behind the box, then through it to the goal) whose trajectories are verified by replay.

It implements only the core hooks of `PlatformKit`, so it serves T1, T2 and train; it refuses T4 with its own
reason and T3/T5 with the interface's default one (the hooks it lacks).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from wsp_data.platforms import KITS, Observation, PlatformKit, Rollout, checked_stream, joint_blocked
from wsp_data.schema import FPS, IMAGE_SIZE, MAX_OBJECTS, PlatformInfo

L1, L2 = 0.30, 0.25  # m: link lengths
HAND_R, BOX_H = 0.03, 0.03  # m: hand radius, box half size
GOAL_TOL = 0.03  # m: the box centre within this of the goal is success
STEP = 0.01  # m: the expert's hand path per step
CAM_Z, CAM_C, FOCAL = 2.0, (0.0, 0.25), 400.0  # top-down pinhole: height (m), centre xy (m), focal length (px)
QLIMITS = np.array([[-math.pi, math.pi]] * 2 + [[-1.0, 1.0]] * 5 + [[0.0, 0.04]] * 2, dtype=np.float32)
INFO = PlatformInfo(
    "planar", FPS, IMAGE_SIZE, IMAGE_SIZE, "top_camera", "planar_2link",
    "joint position targets q0, q1 (rad) + gripper (1 open; unused)", ("q0", "q1", "gripper"),
    "action.ee", "hand target in the world plane (m) + gripper (forward kinematics of the joint targets)",
    ("x", "y", "gripper"), "tests/test_plugin_platform.py: numpy kinematics, OpenCV rendering")


def fk(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Elbow and hand xy (m) of joint angles q (rad)."""
    elbow = np.array([L1 * math.cos(q[0]), L1 * math.sin(q[0])])
    hand = elbow + [L2 * math.cos(q[0] + q[1]), L2 * math.sin(q[0] + q[1])]
    return elbow, hand


def ik(xy: np.ndarray) -> np.ndarray:
    """Joint angles (elbow up, q1 > 0) that put the hand at xy (m)."""
    c = (xy @ xy - L1 ** 2 - L2 ** 2) / (2 * L1 * L2)
    q1 = math.acos(float(np.clip(c, -1.0, 1.0)))
    q0 = math.atan2(xy[1], xy[0]) - math.atan2(L2 * math.sin(q1), L1 + L2 * math.cos(q1))
    return np.array([q0, q1])


HOME = ik(np.array([0.0, 0.15]))  # rad: the hand rests below the box, so its approach never sweeps across it


class PushBoxSpec:
    name = "PushBox"
    instruction = "push the box to the goal"
    objects = ("box",)
    target = "box"


class PlanarWorld:
    """One PushBox scene: reset by seed, step by joint targets, render rgb and robot mask."""

    def __init__(self, render: bool = False):
        self.render, self.qlimits = render, QLIMITS

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        pass

    def reset(self, seed: int) -> Observation:
        rng = np.random.default_rng([seed, 7])
        self.q = HOME.copy()
        self.box = np.array([rng.uniform(-0.1, 0.1), rng.uniform(0.28, 0.36)])
        self.goal = self.box + [rng.uniform(-0.04, 0.04), rng.uniform(0.08, 0.12)]
        return self._observe()

    def step(self, action: np.ndarray) -> Observation:
        self.q = np.asarray(action[:2], dtype=np.float64)  # kinematic joints reach their targets
        _, hand = fk(self.q)
        d = hand - self.box
        # the box is pushed out of the hand: minimal displacement along the line between their centres
        reach = HAND_R + BOX_H
        if np.abs(d).max() < reach:
            n = d / (np.linalg.norm(d) + 1e-12)
            self.box = self.box - n * (reach - np.abs(d).max()) / max(abs(n[0]), abs(n[1]))
        return self._observe()

    def _observe(self) -> Observation:
        _, hand = fk(self.q)
        qpos = np.zeros(9, np.float32)
        qpos[:2], qpos[7:] = self.q, 0.04
        poses = np.full((MAX_OBJECTS, 7), np.nan, np.float32)
        poses[0] = [*self.box, BOX_H, 1, 0, 0, 0]
        contacts = np.zeros(MAX_OBJECTS, bool)
        contacts[0] = np.abs(hand - self.box).max() <= HAND_R + BOX_H + 1e-3
        obs = Observation(qpos, np.array([*hand, 0.05, 1, 0, 0, 0], np.float32), poses, contacts,
                          bool(np.linalg.norm(self.box - self.goal) < GOAL_TOL))
        if self.render:
            obs.rgb, obs.mask, obs.objects = self._draw()
        return obs

    # -- camera ----------------------------------------------------------------------------------------------
    @staticmethod
    def camera_params() -> tuple[np.ndarray, np.ndarray]:
        """OpenCV intrinsics (3, 3) and world→camera extrinsics (3, 4) of the top-down camera."""
        k = np.array([[FOCAL, 0, IMAGE_SIZE / 2], [0, FOCAL, IMAGE_SIZE / 2], [0, 0, 1]])
        r = np.diag([1.0, -1.0, -1.0])
        c = np.array([*CAM_C, CAM_Z])
        return k, np.hstack([r, (-r @ c)[:, None]])

    @staticmethod
    def _px(xy) -> tuple[int, int]:
        """Table-plane xy (m) → pixel, in 1/16 px fixed point (cv2 `shift=4`)."""
        u = FOCAL * (xy[0] - CAM_C[0]) / CAM_Z + IMAGE_SIZE / 2
        v = -FOCAL * (xy[1] - CAM_C[1]) / CAM_Z + IMAGE_SIZE / 2
        return int(round(u * 16)), int(round(v * 16))

    def _draw(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rgb = np.full((IMAGE_SIZE, IMAGE_SIZE, 3), (176, 164, 150), np.uint8)
        mask = np.zeros((IMAGE_SIZE, IMAGE_SIZE), np.uint8)
        objects = np.zeros((IMAGE_SIZE, IMAGE_SIZE), np.uint8)
        px = FOCAL / CAM_Z  # px per m
        cv2.circle(rgb, self._px(self.goal), int(GOAL_TOL * px * 16), (90, 200, 90), 2, cv2.LINE_AA, 4)
        corners = np.array([self._px(self.box + s) for s in np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * BOX_H],
                           np.int32)
        cv2.fillPoly(rgb, [corners], (40, 60, 220), cv2.LINE_AA, 4)
        cv2.fillPoly(objects, [corners], 1, cv2.LINE_8, 4)
        elbow, hand = fk(self.q)
        base, e, h = self._px((0.0, 0.0)), self._px(elbow), self._px(hand)
        for img, colour, aa in ((rgb, (235, 235, 240), cv2.LINE_AA), (mask, 1, cv2.LINE_8)):
            cv2.line(img, base, e, colour, 5, aa, 4)
            cv2.line(img, e, h, colour, 4, aa, 4)
        cv2.circle(rgb, h, int(HAND_R * px * 16), (30, 30, 30), -1, cv2.LINE_AA, 4)
        cv2.circle(mask, h, int(HAND_R * px * 16), 2, -1, cv2.LINE_8, 4)
        objects[mask > 0] = 0  # the arm is drawn over the box
        return rgb, mask, objects

    # -- replay ----------------------------------------------------------------------------------------------
    def replay(self, seed: int, actions, placements=None) -> Rollout:
        actions = checked_stream(actions, 3)
        obs = [self.reset(seed)]
        alt = np.zeros((len(actions), 3), np.float32)
        for t, a in enumerate(actions):
            obs.append(self.step(a))
            alt[t] = [*fk(a[:2].astype(np.float64))[1], a[2]]
        k, e = self.camera_params() if self.render else (None, None)
        return Rollout("PushBox", seed, actions, alt, obs, k, e)


class PlanarExpert:
    """Scripted PushBox expert: the hand goes behind the box (seen from the goal), then pushes it through the
    goal along the box–goal line; a trajectory is returned only if its replay succeeds."""

    spec = PushBoxSpec()

    def __init__(self):
        self.replayer = PlanarWorld(render=False)

    def close(self) -> None:
        self.replayer.close()

    def trajectory(self, seed: int) -> np.ndarray | None:
        w = self.replayer
        w.reset(seed)
        box, goal = w.box.copy(), w.goal.copy()
        d = (goal - box) / np.linalg.norm(goal - box)
        behind = box - d * (HAND_R + BOX_H * math.sqrt(2) + 0.02)
        through = goal - d * (HAND_R + BOX_H)
        path, at = [], fk(HOME)[1]
        for target in (behind, through):
            n = max(1, int(math.ceil(np.linalg.norm(target - at) / STEP)))
            path += [at + (target - at) * (i + 1) / n for i in range(n)]
            at = target
        path += [at] * 10  # hold
        actions = np.array([[*ik(p), 1.0] for p in path], np.float32)
        return actions if w.replay(seed, actions).success else None


class PlanarKit(PlatformKit):
    """The core hooks only: T1, T2 and train; T3/T4/T5 are refused."""

    name = "planar"
    info = INFO
    perturbed_dims = (0, 1)  # a tuple of dimensions (a two-arm platform lists each arm's joints)
    action_bounds = None
    gripper_dim = 2
    gripper_open = 1.0
    default_counts = {"t1": 2}  # what `wsp build` builds when no --count is given

    def unsupported(self, suite: str) -> str | None:
        if suite == "t4":
            return "a top-down 2-D world has no scene objects to spare and no out-of-plane gripper to clamp"
        return super().unsupported(suite)

    def tasks(self) -> dict:
        return {"PushBox": PushBoxSpec()}

    def make_expert(self, task: str):
        return PlanarExpert()

    def make_renderer(self, task: str, objects):
        return PlanarWorld(render=True)

    def joint_stream(self, rollout: Rollout) -> np.ndarray:
        out = np.zeros((len(rollout.actions), 7), np.float32)  # the 2 joint targets, padded to the 7 arm joints
        out[:, :2] = rollout.actions[:, :2]
        return out

    def arm_motion(self, actions: np.ndarray) -> np.ndarray:
        return np.asarray(actions, dtype=np.float64)[:, :2]

    def blocked(self, qpos, tcp_pose, actions) -> bool:
        return joint_blocked(qpos, tcp_pose, self.joint_stream(Rollout("", 0, actions, actions)))

    def render_check(self) -> np.ndarray:
        return PlanarWorld(render=True).reset(0).rgb


@pytest.fixture(scope="module")
def planar():
    """`planar` registered through the registry for this module, then removed again."""
    KITS.register("planar", PlanarKit())
    yield KITS["planar"]
    del KITS._entries["planar"]  # the registry has no public unregister: a test-only clean-up


def test_the_world_renders_frames_masks_and_a_small_joint_change(planar):
    w = planar.make_renderer("PushBox", ("box",))
    a, b = w.reset(3), w.step(np.array([HOME[0] + 0.0025, HOME[1], 1.0]))
    assert a.rgb.shape == (128, 128, 3) and a.rgb.dtype == np.uint8 and a.mask.shape == (128, 128)
    assert set(np.unique(a.mask)) == {0, 1, 2}
    mse = float(((a.rgb.astype(float) - b.rgb.astype(float)) ** 2).mean())
    assert mse > 0  # anti-aliased sub-pixel drawing sees a 0.0025 rad joint change
    ex = planar.make_expert("PushBox")
    assert sum(ex.trajectory(s) is not None for s in range(5)) >= 4


def test_the_render_check_covers_a_plugin_platform_and_rejects_a_bad_frame(planar, monkeypatch, capsys):
    from wsp_data.platforms import render_check

    assert render_check.main(["planar"]) == 0
    assert "render check: planar ok, frame (128, 128, 3)" in capsys.readouterr().out
    monkeypatch.setattr(PlanarKit, "render_check", lambda self: np.zeros((128, 128, 3), np.uint8))
    assert render_check.main(["planar"]) == 1
    assert "planar: bad frame (128, 128, 3) uint8, max 0" in capsys.readouterr().err


def test_a_plugin_platform_builds_a_real_t1_config(planar, tmp_path):
    import json

    import pyarrow.parquet as pq

    from wsp_eval.cli import main

    out = tmp_path / "worldsimprobe"  # the CLI, no --count: the kit's default count
    assert main(["build", "--platform", "planar", "--suite", "t1", "--out", str(out), "--quiet"]) == 0
    assert json.loads((out / "release.json").read_text())["configs"]["t1_planar"]["build_config"]["count"] == 2

    rows = pq.read_table(out / "t1_planar" / "instances.parquet").to_pylist()
    assert len(rows) == 2 and {r["task"] for r in rows} == {"PushBox"}
    for r in rows:
        assert 0 < r["d_os"] < r["d_ol"] and r["perturb_dim"] in (0, 1)
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("worldsimprobe/t1_planar", root=out / "t1_planar")
    assert ds.meta.total_episodes == 6  # original, small, large per instance
    frame = ds[0]
    assert "observation.images.top_camera" in frame and tuple(frame["action"].shape) == (3,)


def test_a_suite_the_platform_cannot_serve_is_refused_with_its_reason(planar, tmp_path):
    from wsp_data.build import build
    from wsp_data.builders import BuildConfig, builder_class

    with pytest.raises(ValueError, match=r"t4 cannot be built on platform 'planar': a top-down 2-D world"):
        build(BuildConfig("t4", "planar", 3, ("PushBox",)), tmp_path / "r", progress=False)
    with pytest.raises(ValueError, match=r"t3 cannot be built on platform 'planar': .*t3_tasks, t3_source"):
        builder_class("t3")(BuildConfig("t3", "planar", 8, ("PushBox",)))
    with pytest.raises(ValueError, match=r"t5 cannot be built on platform 'planar': .*t5_primitives"):
        builder_class("t5")(BuildConfig("t5", "planar", 4, ("PushBox",)))
