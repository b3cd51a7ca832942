"""LIBERO (robosuite 1.4 on MuJoCo, CPU) platform: replays LIBERO's native 7-D OSC stream (end-effector
position delta, axis-angle rotation delta, gripper; each in [−1, 1], gripper −1 open … +1 closed) and
records what a rollout stores — the 128×128 `agentview` RGB (flipped upright), an exact robot label mask
from MuJoCo geom segmentation, robot joint and finger positions, the end-effector pose, task object poses,
robot–object contact flags, camera parameters, task success (the BDDL goal) — plus the joint-space stream
(the 7 joint positions each action reached, and the gripper command) beside the native one.

Scenes: scene seed s lays the task's objects out with LIBERO's own placement samplers driven by
`np.random.seed(s)` (the global RNG is restored afterwards), then `SETTLE_STEPS` zero actions let them come
to rest; that state is frame 0. A replay restores the cached frame-0 state after `mj_resetData`, so the same
seed and stream give bit-identical rollouts whatever ran before.
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import os
from dataclasses import dataclass

import numpy as np

from wsp_data.platforms import Observation, PlatformError, Rollout, checked_stream
from wsp_data.platforms.libero.runtime import configure_libero
from wsp_data.schema import IMAGE_SIZE, MAX_OBJECTS

_PATHS = configure_libero()

import mujoco  # noqa: E402
from libero.libero import benchmark  # noqa: E402
from libero.libero.envs import OffScreenRenderEnv  # noqa: E402
from libero.libero.envs.env_wrapper import ControlEnv  # noqa: E402

logging.getLogger("robosuite_logs").setLevel(logging.ERROR)  # robosuite's own logger
# MuJoCo keeps the decoded meshes and textures of every model it compiles, up to 0.5 GB per process, which LIBERO's
# scenes fill: a build worker compiles each task's models about once (slots are ordered by task), so the cache
# would only hold memory (measured: a 12-slot T4 build's worker peak 3.4 → 3.0 GB, +2–4 s per simulator made)
mujoco.mj_setCacheCapacity(mujoco.mj_getCache(), 0)

CAMERA = "agentview"
ACTION_DIM = 7
JOINT_ACTION_DIM = 8  # 7 joint positions reached + gripper command
GRIPPER_OPEN, GRIPPER_CLOSED = -1.0, 1.0
MASK_ARM, MASK_DISTAL = 1, 2
LAYOUT_PASSES = 4  # seeded resets allowed for a scene's layout to stop depending on the one before (`_lay_out`)
SETTLE_STEPS = 10  # zero actions after layout, before frame 0: objects dropped by the sampler come to rest
DISTAL_BODIES = ("robot0_link7", "robot0_right_hand")  # plus every gripper0_* body (hand, fingers, pads)
SUITES = ("libero_object", "libero_spatial", "libero_goal", "libero_10", "libero_90")


@dataclass(frozen=True)
class LiberoTask:
    """One LIBERO task: `name` is `<suite>/<task name>` (e.g. `libero_object/pick_up_the_..._basket`)."""

    suite: str
    index: int
    task_name: str
    instruction: str
    bddl_file: str

    @property
    def name(self) -> str:
        return f"{self.suite}/{self.task_name}"


def libero_task(name: str) -> LiberoTask:
    suite, _, task_name = name.partition("/")
    if suite not in SUITES or not task_name:
        raise PlatformError(f"unknown LIBERO task {name!r}: expected '<suite>/<task name>' with suite in {SUITES}")
    with contextlib.redirect_stdout(io.StringIO()):
        bench = benchmark.get_benchmark_dict()[suite]()
    for i in range(bench.n_tasks):
        t = bench.get_task(i)
        if t.name == task_name:
            return LiberoTask(suite, i, t.name, t.language,
                              os.path.join(_PATHS["bddl_files"], t.problem_folder, t.bddl_file))
    raise PlatformError(f"{suite} has no task {task_name!r}")


def _quat_wxyz(mat: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(mat, dtype=np.float64).reshape(9))
    return q


class LiberoPlatform:
    """One LIBERO env for one task, kept alive across many rollouts."""

    def __init__(self, task: str, *, render: bool = True, objects: tuple[str, ...] | None = None):
        self.spec = libero_task(task)
        self.task, self.render = task, render
        kw = dict(camera_names=[CAMERA], camera_heights=IMAGE_SIZE, camera_widths=IMAGE_SIZE,
                  use_camera_obs=False, ignore_done=True, horizon=100_000, hard_reset=False)
        with contextlib.redirect_stdout(io.StringIO()):  # a state-only env gets no GL context at all
            self.env = (OffScreenRenderEnv(bddl_file_name=self.spec.bddl_file, **kw) if render else
                        ControlEnv(bddl_file_name=self.spec.bddl_file, has_renderer=False,
                                   has_offscreen_renderer=False, **kw))
        self.u = self.env.env
        self.sim = self.u.sim
        self.model = self.sim.model._model
        self.data = self.sim.data._data
        self.robot = self.u.robots[0]
        self._index_robot()
        self.track(tuple(objects) if objects is not None else tuple(self.u.obj_of_interest))
        self._scenes: dict[int, tuple[np.ndarray, ...]] = {}
        self._fk = mujoco.MjData(self.model)
        self._owner = True  # False on an `unrendered` view: its `close` leaves the env open

    # -- lifecycle ------------------------------------------------------------------------------
    def unrendered(self) -> LiberoPlatform:
        """This env as a state-only platform: the same simulator, scene cache and tracked objects, observations
        without images (its steps cost what a state-only env's do). Closing it leaves the env open."""
        view = copy.copy(self)
        view.render, view._owner = False, False
        return view

    def close(self) -> None:
        """Free the env (a view from `unrendered` leaves it to its platform) and drop the references to it, so
        that its memory returns now, not when this object goes."""
        if not self._owner or self.env is None:
            return
        ctx = self.sim._render_context_offscreen if self.render else None
        if ctx is not None:  # MuJoCo frees GL objects in whichever context is current: make it this env's own
            ctx.gl_ctx.make_current()
            ctx.con.free()
            ctx.gl_ctx.free()
        self.env.close()
        self.env = self.u = self.sim = self.model = self.data = self.robot = self._fk = None

    def __enter__(self) -> LiberoPlatform:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- scene facts ------------------------------------------------------------------------------
    def _index_robot(self) -> None:
        m = self.model
        names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or "" for b in range(m.nbody)]
        body_label = np.zeros(m.nbody, dtype=np.uint8)
        for b, n in enumerate(names):
            if n.startswith("gripper0_") or n in DISTAL_BODIES:
                body_label[b] = MASK_DISTAL
            elif n.startswith("robot0_"):
                body_label[b] = MASK_ARM
        self.robot_bodies = np.nonzero(body_label)[0]
        self.geom_label = body_label[m.geom_bodyid]  # geom id → mask label
        joints = self.robot._ref_joint_pos_indexes
        self.qpos_index = np.array(list(joints) + list(self.robot._ref_gripper_joint_pos_indexes))
        arm_joint_ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in self.robot.robot_joints]
        finger_ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)
                      for j in self.robot.gripper.joints]
        self.qlimits = np.array(m.jnt_range[arm_joint_ids + finger_ids], dtype=np.float32)
        self.eef_site = self.robot.eef_site_id
        self.camera_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, CAMERA)
        self._base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "robot0_base")
        self._collision = np.nonzero((m.geom_contype | m.geom_conaffinity) != 0)[0]

    def track(self, objects: tuple[str, ...]) -> None:
        """Record poses and contacts of `objects` (movable objects or fixtures), in this order."""
        if len(objects) > MAX_OBJECTS:
            raise PlatformError(f"{self.task}: {len(objects)} objects exceed MAX_OBJECTS={MAX_OBJECTS}")
        m = self.model
        self.object_names = tuple(objects)
        self.body_of = {name: self.body(name) for name in objects}
        self.geom_object = np.full(m.ngeom, -1, dtype=np.int64)  # geom id → index of the object holding it
        for k, name in enumerate(objects):
            self.geom_object[np.isin(m.geom_bodyid, self.bodies_under(self.body_of[name]))] = k

    def body(self, name: str) -> int:
        """The root body of a scene object (movable or fixture)."""
        entity = self.u.objects_dict.get(name) or self.u.fixtures_dict.get(name)
        if entity is None:
            raise PlatformError(f"{self.task} has no object {name!r}")
        return mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, entity.root_body)

    def bodies_under(self, root: int) -> list[int]:
        return [b for b in range(self.model.nbody) if self._descends(b, root)]

    def object_pose(self, name: str) -> np.ndarray:
        """World pose (xyz + quaternion wxyz) of an object's root body: its free joint's coordinates."""
        b = self.body(name)
        return np.concatenate([self.data.xpos[b], self.data.xquat[b]])

    def movable_objects(self) -> tuple[str, ...]:
        """Objects with a free joint (fixtures such as tables, cabinets and stoves excluded)."""
        return tuple(n for n, o in self.u.objects_dict.items() if o.joints)

    def collision_points(self, name: str, frame: str = "world") -> np.ndarray:
        """Corners of the boxes around an object's collision geoms, in the world or its body frame, (N, 3)."""
        root = self.body(name)
        bodies = self.bodies_under(root)
        geoms = [g for g in self._collision if int(self.model.geom_bodyid[g]) in bodies]
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
        d = self.data
        pts = np.concatenate([(self.model.geom_aabb[g, :3] + signs * self.model.geom_aabb[g, 3:])
                              @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g] for g in geoms])
        if frame == "body":
            return (pts - d.xpos[root]) @ d.xmat[root].reshape(3, 3)
        return pts

    def link_positions(self, qpos: np.ndarray) -> np.ndarray:
        """World origins of every robot body for each row of `qpos` (T, 9) by forward kinematics: (T·B, 3)."""
        fk = self._fk
        fk.qpos[:] = self.data.qpos
        out = []
        for q in np.asarray(qpos, dtype=np.float64):
            fk.qpos[self.qpos_index] = q
            mujoco.mj_kinematics(self.model, fk)
            out.append(np.array(fk.xpos[self.robot_bodies]))
        return np.concatenate(out)

    def base_xy(self) -> np.ndarray:
        """World xy of the robot's base."""
        return np.array(self.data.xpos[self._base][:2])

    def _descends(self, body: int, ancestor: int) -> bool:
        while body > 0:
            if body == ancestor:
                return True
            body = int(self.model.body_parentid[body])
        return False

    # -- scenes and stepping ----------------------------------------------------------------------
    def _lay_out(self, seed: int) -> None:
        """LIBERO's layout of scene `seed`, the same whatever ran before. Its sampler places an object that starts
        on another (a bowl on a cookie box) relative to where the simulator last saw that other object — the
        previous episode's pose, not the one just sampled — so one seeded reset depends on history (measured: the
        bowl 7 mm off between two processes). Resetting with the same seed until the layout repeats reaches the
        layout in which each object sits where the sampler meant it (2–3 resets)."""
        saved = np.random.get_state()
        previous = None
        try:
            for _ in range(LAYOUT_PASSES):
                np.random.seed(int(seed) % 2**32)
                with contextlib.redirect_stdout(io.StringIO()):
                    self.env.reset()
                state = self.sim.get_state().flatten()
                if previous is not None and np.array_equal(state, previous):
                    return
                previous = np.array(state)
        finally:
            np.random.set_state(saved)
        raise PlatformError(f"{self.task}: scene {seed}'s layout still changed after {LAYOUT_PASSES} seeded resets")

    def scene_state(self, seed: int) -> tuple[np.ndarray, ...]:
        """Frame 0 of scene `seed` (cached): the flattened MuJoCo state and the controller's stateful parts
        (OSC goal orientation, which persists while rotation deltas are zero, and the gripper command)."""
        if seed not in self._scenes:
            self._lay_out(seed)
            # robosuite keeps the gripper's command ramp across resets: clear it, so frame 0 never depends on
            # the episode that ran before (the controller itself is rebuilt by the reset)
            self.robot.gripper.current_action = np.zeros_like(self.robot.gripper.current_action)
            for _ in range(SETTLE_STEPS):
                self.u.step(np.array([0, 0, 0, 0, 0, 0, GRIPPER_OPEN]))
            c = self.robot.controller
            self._scenes[seed] = (np.array(self.sim.get_state().flatten()), np.array(c.goal_pos),
                                  np.array(c.goal_ori), np.array(self.robot.gripper.current_action))
        return self._scenes[seed]

    def reset(self, seed: int, placements: dict[str, np.ndarray] | None = None) -> Observation:
        """Restore scene `seed`'s frame 0 from a clean MuJoCo data block (no solver warm start carried over)
        and its controller state, then move free objects to `placements` (name → world xyz + quaternion wxyz,
        at rest)."""
        state, goal_pos, goal_ori, grip = self.scene_state(seed)
        mujoco.mj_resetData(self.model, self.data)
        self.sim.set_state_from_flattened(state)
        if placements:
            for name, pose in placements.items():
                self.set_object_pose(name, np.asarray(pose, dtype=np.float64))
        self.sim.forward()
        c = self.robot.controller
        c.goal_pos, c.goal_ori = goal_pos.copy(), goal_ori.copy()
        self.robot.gripper.current_action = grip.copy()
        c.update(force=True)
        return self._observe()

    def set_object_pose(self, name: str, pose: np.ndarray) -> None:
        entity = self.u.objects_dict.get(name)
        if entity is None or not entity.joints:
            raise PlatformError(f"{self.task}: {name!r} is not a free object")
        self.sim.data.set_joint_qpos(entity.joints[-1], pose)
        self.sim.data.set_joint_qvel(entity.joints[-1], np.zeros(6))

    def step(self, action: np.ndarray) -> Observation:
        self.u.step(np.asarray(action, dtype=np.float64))
        return self._observe()

    def _observe(self) -> Observation:
        d = self.data
        poses = np.full((MAX_OBJECTS, 7), np.nan, dtype=np.float32)
        for k, name in enumerate(self.object_names):
            b = self.body_of[name]
            poses[k, :3], poses[k, 3:] = d.xpos[b], d.xquat[b]
        ob = Observation(
            qpos=np.asarray(d.qpos[self.qpos_index], dtype=np.float32),
            tcp_pose=np.concatenate([d.site_xpos[self.eef_site], _quat_wxyz(d.site_xmat[self.eef_site])]).astype(np.float32),
            object_poses=poses, contacts=self.contacts(), success=bool(self.u._check_success()),
        )
        if self.render:
            ob.rgb, ob.mask, ob.objects = self.render_frame()
        return ob

    def contacts(self) -> np.ndarray:
        """(MAX_OBJECTS,) bool: a robot geom touches a geom of task object k in this step's contact list."""
        out = np.zeros(MAX_OBJECTS, dtype=bool)
        d = self.data
        for i in range(d.ncon):
            g1, g2 = d.contact[i].geom1, d.contact[i].geom2
            for robot_geom, other in ((g1, g2), (g2, g1)):
                if self.geom_label[robot_geom] and self.geom_object[other] >= 0:
                    out[self.geom_object[other]] = True
        return out

    def render_frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Upright RGB (128, 128, 3) uint8, robot label mask (128, 128) uint8 of the evaluated camera and the
        tracked objects' label image (128, 128) uint8 (k + 1 where object k is the visible surface, else 0)."""
        ctx = self.sim._render_context_offscreen
        if ctx is None:
            raise PlatformError("no offscreen render context: the platform was created without a renderer")
        ctx.gl_ctx.make_current()  # robosuite renders into whichever GL context is current: several envs live here
        size = IMAGE_SIZE
        rgb = np.empty((size, size, 3), dtype=np.uint8)
        ctx.render(width=size, height=size, camera_id=self.camera_id, segmentation=False)
        mujoco.mjr_readPixels(rgb=rgb, depth=None, viewport=mujoco.MjrRect(0, 0, size, size), con=ctx.con)
        ids = np.empty((size, size, 3), dtype=np.uint8)
        ctx.render(width=size, height=size, camera_id=self.camera_id, segmentation=True)
        mujoco.mjr_readPixels(rgb=ids, depth=None, viewport=mujoco.MjrRect(0, 0, size, size), con=ctx.con)
        # robosuite 1.4 packs these ids in uint8 and overflows under numpy 2: unpack in int64 here
        seg = ids[..., 0].astype(np.int64) + (ids[..., 1].astype(np.int64) << 8) + (ids[..., 2].astype(np.int64) << 16)
        scn = ctx.scn
        lut = np.zeros(scn.ngeom + 1, dtype=np.uint8)
        olut = np.zeros(scn.ngeom + 1, dtype=np.uint8)
        for i in range(scn.ngeom):
            g = scn.geoms[i]
            if g.segid != -1 and g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                lut[g.segid + 1] = self.geom_label[g.objid]
                olut[g.segid + 1] = self.geom_object[g.objid] + 1
        seg[seg > scn.ngeom] = 0
        return (np.ascontiguousarray(rgb[::-1]), np.ascontiguousarray(lut[seg][::-1]),
                np.ascontiguousarray(olut[seg][::-1]))

    def camera_params(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV intrinsics (3, 3) and world→camera extrinsics (3, 4) of the upright evaluated view."""
        m, d, c = self.model, self.data, self.camera_id
        f = 0.5 * IMAGE_SIZE / np.tan(np.deg2rad(m.cam_fovy[c]) / 2)
        K = np.array([[f, 0, IMAGE_SIZE / 2], [0, f, IMAGE_SIZE / 2], [0, 0, 1]], dtype=np.float32)
        cam_to_world = d.cam_xmat[c].reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])  # MuJoCo → OpenCV axes
        R = cam_to_world.T
        return K, np.concatenate([R, (-R @ d.cam_xpos[c])[:, None]], axis=1).astype(np.float32)

    # -- replay -----------------------------------------------------------------------------------
    def replay(self, seed: int, actions: np.ndarray, placements: dict[str, np.ndarray] | None = None) -> Rollout:
        """Restore scene `seed` (and `placements`) and execute a (T, 7) OSC stream, recording every frame."""
        actions = checked_stream(actions, ACTION_DIM)
        ro = Rollout(self.task, int(seed), actions, np.zeros((len(actions), JOINT_ACTION_DIM), dtype=np.float32))
        ro.observations.append(self.reset(seed, placements))
        if self.render:
            ro.intrinsic, ro.extrinsic = self.camera_params()
        for t, a in enumerate(actions):
            ob = self.step(a)
            ro.observations.append(ob)
            ro.alt_actions[t, :7], ro.alt_actions[t, 7] = ob.qpos[:7], a[6]
        return ro
