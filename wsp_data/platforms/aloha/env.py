"""ALOHA (two ViperX 300s arms, gym-aloha 0.1.5's MJCF on MuJoCo 3.8, CPU) platform: replays the native 14-D
joint-target stream (per arm 6 joint positions in rad, then a gripper command g in [0, 1], 1 open … 0 closed, in
gym-aloha's normalisation; left arm first) and records what a rollout stores — the 320×240 `head` RGB, an exact
robot label mask from MuJoCo geom segmentation, both arms' joint and finger positions, both grip points' poses,
task object poses, robot–object contact flags, camera parameters, task success (from state) — plus the
end-effector stream beside the native one (the grip point each joint target reaches by forward kinematics, as
xyz + XYZ Euler, and the gripper command, per arm).

Scene: gym-aloha's joint-position transfer-cube MJCF, edited through `MjSpec`: a `head` camera, a grip-point
site per arm, the task's objects and one spare `distractor` cube parked out of sight behind the camera (on a
hidden pedestal) that a placement can move onto the table; a scene may add props (`PROPS`: T5's knock-over
block), parked likewise, last in the model so that every other body keeps its id. Control runs at 20 Hz (25
physics steps of 0.002 s per action, where gym-aloha runs at 50 Hz) because the benchmark stores 20 fps
episodes.

Scenes: scene seed s lays the task's objects out from `np.random.default_rng(s)` (placements then override any
named object's pose), and `SETTLE_STEPS` home-pose actions (fingers open) let them come to rest; that state is
frame 0. A reset restores the cached frame-0 state after `mj_resetData`, so the same seed and stream give
bit-identical rollouts whatever ran before.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wsp_data.platforms import Observation, PlatformError, Rollout, checked_stream
from wsp_data.platforms.aloha.runtime import SCENE_XML, configure_aloha, offscreen_renderer
from wsp_data.schema import MAX_OBJECTS

_ASSETS = configure_aloha()

import mujoco  # noqa: E402

CAMERA = "head"
WIDTH, HEIGHT = 320, 240
ACTION_DIM = 14  # per arm: 6 joint targets (rad) + gripper g
EE_ACTION_DIM = 14  # per arm: grip point xyz (m, world) + XYZ Euler (rad) + gripper g
SUBSTEPS = 25  # physics steps (0.002 s) per action: 20 Hz
SETTLE_STEPS = 4  # home-pose actions after layout, before frame 0 (0.2 s)
ARMS = ("left", "right")
HOME = np.array([0.0, -0.96, 1.16, 0.0, -0.3, 0.0])  # gym-aloha's START_ARM_POSE (arm joints)
GRIP_CLOSED, GRIP_OPEN = 0.01844, 0.05800  # finger slide (m) at g = 0 and g = 1 (gym-aloha's normalisation)
TCP_X = 0.13  # m: grip point on the gripper_link x axis (fingertips reach 0.154), between the finger pads
MASK_ARM, MASK_DISTAL = 1, 2
ARM_LINKS = ("shoulder_link", "upper_arm_link", "upper_forearm_link", "lower_forearm_link")  # + the base geom
PARK = np.array([0.0, -1.5, 0.02])  # the distractor's parking spot: behind the head camera, out of reach
HEAD = dict(pos=[0.0, -0.25, 0.9], fovy=62.0)  # looks at the table body (targetbody mode)
# joint qpos addresses: [left arm 6, right arm 6, left arm's left_finger, right arm's left_finger]
QPOS_INDEX = np.array([0, 1, 2, 3, 4, 5, 8, 9, 10, 11, 12, 13, 6, 14])


def grip_position(g: float | np.ndarray) -> float | np.ndarray:
    """Finger slide target (m) of a gripper command (MuJoCo clips it to the actuator range 0.021 … 0.057)."""
    return g * (GRIP_OPEN - GRIP_CLOSED) + GRIP_CLOSED


def quat_wxyz(mat: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(mat, dtype=np.float64).reshape(9))
    return q


def euler_xyz(mat: np.ndarray) -> np.ndarray:
    """Intrinsic XYZ Euler angles (rad) of a rotation matrix: R = Rx(a) Ry(b) Rz(c) (ManiSkill's convention)."""
    R = np.asarray(mat, dtype=np.float64).reshape(3, 3)
    return np.array([np.arctan2(-R[1, 2], R[2, 2]), np.arcsin(np.clip(R[0, 2], -1, 1)), np.arctan2(-R[0, 1], R[0, 0])])


# -- objects -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Part:
    """One box geom of an object, in the object's frame (m)."""

    pos: tuple[float, float, float]
    half: tuple[float, float, float]
    name: str = ""


@dataclass(frozen=True)
class ObjectSpec:
    """A free rigid object of boxes; its pose is its body origin (at rest, `rest_z` above the table)."""

    parts: tuple[Part, ...]
    rgba: tuple[float, float, float, float]
    mass: float
    rest_z: float


def _box(h: tuple[float, float, float], rgba, mass: float) -> ObjectSpec:
    return ObjectSpec((Part((0, 0, 0), h),), rgba, mass, h[2])


def _bin() -> ObjectSpec:  # open box: 12 × 12 cm inside, walls 5 cm high and 4 mm thick; origin at the floor's bottom
    b, t, h = 0.06, 0.004, 0.05
    return ObjectSpec((Part((0, 0, t / 2), (b + 2 * t, b + 2 * t, t / 2)),
                       Part((b + t, 0, h / 2), (t, b + 2 * t, h / 2)), Part((-b - t, 0, h / 2), (t, b + 2 * t, h / 2)),
                       Part((0, b + t, h / 2), (b, t, h / 2)), Part((0, -b - t, h / 2), (b, t, h / 2))),
                      (0.2, 0.4, 1.0, 1.0), 0.3, 0.0)


def _socket() -> ObjectSpec:  # gym-aloha's socket: 4 walls (a 3.6 cm square bore, 12 cm long) around a pin
    w, t, L = 0.02, 0.002, 0.06
    return ObjectSpec((Part((0, 0, -w), (L, w + t, t)), Part((0, 0, w), (L, w + t, t)),
                       Part((0, w, 0), (L, t, w - t)), Part((0, -w, 0), (L, t, w - t)),
                       Part((0, 0, 0), (0.04, 0.01, 0.01), "pin")), (0.0, 0.0, 1.0, 1.0), 0.05, w + t)


OBJECTS: dict[str, ObjectSpec] = {
    "red_cube": _box((0.02, 0.02, 0.02), (1.0, 0.0, 0.0, 1.0), 0.05),  # gym-aloha's own `box`, kept as shipped
    "green_cube": _box((0.02, 0.02, 0.02), (0.0, 0.8, 0.0, 1.0), 0.05),
    "bar": _box((0.15, 0.02, 0.02), (1.0, 0.6, 0.0, 1.0), 0.1),
    "bin": _bin(),
    "peg": _box((0.06, 0.01, 0.01), (1.0, 0.0, 0.0, 1.0), 0.05),
    "socket": _socket(),
    "distractor": _box((0.02, 0.02, 0.02), (1.0, 0.9, 0.1, 1.0), 0.05),
    "tall_block": _box((0.015, 0.015, 0.05), (0.6, 0.2, 0.8, 1.0), 0.06),  # a 3 × 3 × 10 cm prop (T5's knock-over)
}
DISTRACTOR = "distractor"
PROPS = ("tall_block",)  # objects a scene may add beside its task's own (`AlohaPlatform(extras=…)`)


# -- tasks ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class AlohaTask:
    """One ALOHA task: the objects it records (target first), the xy box (world, m) each is laid out in, and its
    success test on the platform's current state."""

    name: str
    instruction: str
    objects: tuple[str, ...]
    layout: tuple[tuple[float, float, float, float], ...]  # per object: x_lo, x_hi, y_lo, y_hi
    success_test: Callable[[AlohaPlatform], bool] = field(compare=False, repr=False)

    @property
    def target(self) -> str:
        return self.objects[0]


def _held_by(p: AlohaPlatform, name: str, arm: str, lift: float = 0.05) -> bool:
    """`name` is off the table, at least `lift` above its resting height, touched by `arm` and not the other."""
    t = p.touching(name)
    return (t[arm] and not t[ARMS[1 - ARMS.index(arm)]] and not t["table"]
            and p.object_pose(name)[2] > OBJECTS[name].rest_z + lift)


def _resting_on(p: AlohaPlatform, top: str, base: str, dz: float, xy_tol: float) -> bool:
    a, b = p.object_pose(top), p.object_pose(base)
    return (abs(a[2] - b[2] - dz) < 0.008 and np.linalg.norm(a[:2] - b[:2]) < xy_tol
            and not p.touching(top)["robot"])


def _pushed(p: AlohaPlatform) -> bool:
    x0, x = p.start_poses["red_cube"], p.object_pose("red_cube")
    return x0[0] - x[0] > 0.08 and abs(x[1] - x0[1]) < 0.03 and x[2] < 0.03 and not p.touching("red_cube")["robot"]


def _in_bin(p: AlohaPlatform) -> bool:
    c, b = p.object_pose("red_cube"), p.object_pose("bin")
    local = (c[:3] - b[:3]) @ p.body_rotation("bin")
    return bool(np.all(np.abs(local[:2]) < 0.06) and local[2] < 0.05 and not p.touching("red_cube")["robot"])


def _two_arm_lift(p: AlohaPlatform) -> bool:
    t = p.touching("bar")
    return t["left"] and t["right"] and not t["table"] and p.object_pose("bar")[2] > 0.1


def _inserted(p: AlohaPlatform) -> bool:
    return p.pin_touched() and not p.touching("peg")["table"] and not p.touching("socket")["table"]


_RIGHT_HALF, _LEFT_HALF = (0.0, 0.2, 0.4, 0.6), (-0.2, 0.0, 0.4, 0.6)
TASK_LIST: tuple[AlohaTask, ...] = (
    AlohaTask("transfer_cube", "Pick up the red cube with the right arm and pass it to the left arm.",
              ("red_cube",), (_RIGHT_HALF,), lambda p: _held_by(p, "red_cube", "left")),
    AlohaTask("peg_insertion", "Pick up the red peg and the blue socket, one in each hand, and insert the peg "
              "into the socket in mid-air.", ("peg", "socket"), ((0.1, 0.2, 0.4, 0.6), (-0.2, -0.1, 0.4, 0.6)),
              _inserted),
    AlohaTask("lift_cube", "Lift the red cube with the right arm.", ("red_cube",), (_RIGHT_HALF,),
              lambda p: _held_by(p, "red_cube", "right", 0.08)),
    AlohaTask("push_cube", "Push the red cube to the left.", ("red_cube",), ((0.05, 0.2, 0.4, 0.6),), _pushed),
    AlohaTask("cube_in_bin", "Put the red cube into the blue bin.", ("red_cube", "bin"),
              ((0.06, 0.2, 0.42, 0.58), (-0.12, -0.04, 0.42, 0.58)), _in_bin),
    AlohaTask("stack_cubes", "Stack the red cube on the green cube.", ("red_cube", "green_cube"),
              ((0.05, 0.2, 0.42, 0.58), (-0.1, -0.02, 0.42, 0.58)),
              lambda p: _resting_on(p, "red_cube", "green_cube", 0.04, 0.02)),
    AlohaTask("hand_over", "Pick up the red cube with the left arm and hand it over to the right arm.",
              ("red_cube",), (_LEFT_HALF,), lambda p: _held_by(p, "red_cube", "right")),
    AlohaTask("two_arm_lift", "Lift the orange bar with both arms.", ("bar",), ((-0.03, 0.03, 0.45, 0.55),),
              _two_arm_lift),
)
TASKS: dict[str, AlohaTask] = {t.name: t for t in TASK_LIST}


def aloha_task(name: str) -> AlohaTask:
    if name not in TASKS:
        raise PlatformError(f"unknown ALOHA task {name!r}: expected one of {tuple(TASKS)}")
    return TASKS[name]


def layout(task: AlohaTask, seed: int) -> dict[str, np.ndarray]:
    """Scene `seed`'s object poses (world xyz + wxyz, axis-aligned, at rest on the table)."""
    rng = np.random.default_rng(int(seed))
    poses = {}
    for name, (x0, x1, y0, y1) in zip(task.objects, task.layout):
        poses[name] = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), OBJECTS[name].rest_z, 1, 0, 0, 0])
    return poses


# -- scene ---------------------------------------------------------------------------------------------
def park(k: int) -> np.ndarray:
    """Parking spot of the scene's k-th spare object (0: the distractor, then the props), behind the camera."""
    return PARK + [0.15 * k, 0, 0]


def build_model(objects: Sequence[str], extras: Sequence[str] = ()) -> mujoco.MjModel:
    """The joint-position transfer-cube scene with the head camera, grip-point sites, `objects`, the parked
    distractor and the parked `extras` (props; added last, so the other bodies and geoms keep their ids;
    gym-aloha's red `box` becomes `red_cube`, or is removed when unused)."""
    spec = mujoco.MjSpec.from_file(str(_ASSETS / SCENE_XML))
    spec.delete(spec.keys[0])  # the keyframe's qpos no longer matches the edited scene
    cam = spec.worldbody.add_camera(name=CAMERA, pos=HEAD["pos"], fovy=HEAD["fovy"])
    cam.mode, cam.targetbody = mujoco.mjtCamLight.mjCAMLIGHT_TARGETBODY, "table"
    for arm in ARMS:
        spec.body(f"vx300s_{arm}/gripper_link").add_site(name=f"vx300s_{arm}/tcp", pos=[TCP_X, 0, 0], size=[0.005])
    box = spec.body("box")
    if "red_cube" in objects:
        box.name = "red_cube"
    else:
        spec.delete(box)
    for name in [o for o in objects if o != "red_cube"] + [DISTRACTOR, *extras]:
        o = OBJECTS[name]
        body = spec.worldbody.add_body(name=name, pos=[0, 0, o.rest_z])
        body.add_freejoint(name=f"{name}_joint")
        # the scene's compiler takes inertia from geom groups 4-5 only: set it explicitly (a solid box of the parts)
        lo = np.min([np.subtract(p.pos, p.half) for p in o.parts], axis=0)
        hi = np.max([np.add(p.pos, p.half) for p in o.parts], axis=0)
        s = (hi - lo) ** 2
        body.explicitinertial, body.mass = True, o.mass
        body.ipos, body.iquat = (lo + hi) / 2, [1, 0, 0, 0]  # MjSpec keeps the body position as ipos otherwise
        body.inertia = o.mass / 12 * np.array([s[1] + s[2], s[0] + s[2], s[0] + s[1]])
        for k, part in enumerate(o.parts):
            body.add_geom(name=part.name or f"{name}_{k}", type=mujoco.mjtGeom.mjGEOM_BOX, pos=part.pos,
                          size=part.half, rgba=o.rgba, condim=4, friction=[1, 0.005, 0.0001])
    for k, name in enumerate(["", *extras]):
        spot = park(k)
        pedestal = spec.worldbody.add_body(name=f"parking{name and '_' + name}", pos=[spot[0], spot[1], -0.01])
        pedestal.add_geom(name=pedestal.name, type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.05, 0.05, 0.01], group=3)
    model = spec.compile()
    model.vis.quality.offsamples, model.vis.quality.shadowsize = 0, 1024  # 3× cheaper than 4× MSAA + 4096 shadows
    return model


class AlohaPlatform:
    """One ALOHA scene for one task, kept alive across many rollouts."""

    def __init__(self, task_name: str, render: bool, objects: Sequence[str] | None = None,
                 extras: Sequence[str] = ()):
        self.spec = aloha_task(task_name)
        self.task, self.render, self.extras = task_name, render, tuple(extras)
        unknown = [e for e in self.extras if e not in PROPS]
        if unknown:
            raise PlatformError(f"{task_name}: no prop {unknown[0]!r}; props: {PROPS}")
        self.model = build_model(self.spec.objects, self.extras)
        self.data = mujoco.MjData(self.model)
        self._fk = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)  # the head camera's pose (fixed in the world) for camera_params
        self._index()
        self.track(tuple(objects) if objects is not None else self.spec.objects)
        self._scenes: dict[int, np.ndarray] = {}
        self.start_poses: dict[str, np.ndarray] = {}  # frame-0 object poses of the current episode
        self._renderer = offscreen_renderer()(self.model, HEIGHT, WIDTH) if render else None

    # -- lifecycle ------------------------------------------------------------------------------
    def close(self) -> None:
        """Free the renderer. MuJoCo 3.8's `Renderer.close` frees the GL context first and then the MuJoCo
        render context in whatever context is current — another platform's, whose textures it deletes (its next
        segmentation render returns garbage). So our context is made current and the render context freed
        first."""
        r, self._renderer = getattr(self, "_renderer", None), None  # None also when __init__ failed
        if r is None:
            return
        if r._gl_context is not None and r._mjr_context is not None:
            r._gl_context.make_current()
            r._mjr_context.free()
            r._mjr_context = None
        r.close()

    def __del__(self) -> None:  # a platform dropped unclosed must not free its renderer the unsafe way
        self.close()

    def __enter__(self) -> AlohaPlatform:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- scene facts ------------------------------------------------------------------------------
    def _index(self) -> None:
        m = self.model
        J = mujoco.mjtObj
        self.geom_label = np.zeros(m.ngeom, dtype=np.uint8)  # 0 not robot, 1 arm, 2 wrist / gripper / fingers
        self.geom_arm = np.full(m.ngeom, -1, dtype=np.int64)  # 0 left, 1 right
        for g in range(m.ngeom):
            body = m.body(m.geom_bodyid[g]).name
            for k, arm in enumerate(ARMS):
                root = f"vx300s_{arm}"
                if body == root or body.startswith(root + "/"):
                    self.geom_arm[g] = k
                    self.geom_label[g] = MASK_ARM if body == root or body[len(root) + 1:] in ARM_LINKS else MASK_DISTAL
        self.tcp_sites = [mujoco.mj_name2id(m, J.mjOBJ_SITE, f"vx300s_{a}/tcp") for a in ARMS]
        self.camera_id = mujoco.mj_name2id(m, J.mjOBJ_CAMERA, CAMERA)
        self.table_geom = mujoco.mj_name2id(m, J.mjOBJ_GEOM, "table")
        pin = mujoco.mj_name2id(m, J.mjOBJ_GEOM, "pin")
        self.pin_geom = pin if pin >= 0 else None
        self.qlimits = np.array(m.jnt_range[QPOS_INDEX], dtype=np.float64)
        self.free = {}  # object name → (body id, qpos address, dof address)
        for j in range(m.njnt):
            if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                b = int(m.jnt_bodyid[j])
                self.free[m.body(b).name] = (b, int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j]))

    def track(self, objects: tuple[str, ...]) -> None:
        """Record poses and contacts of `objects` (names of the scene's free objects), in this order."""
        if len(objects) > MAX_OBJECTS:
            raise PlatformError(f"{self.task}: {len(objects)} objects exceed MAX_OBJECTS={MAX_OBJECTS}")
        unknown = [o for o in objects if o not in self.free]
        if unknown:
            raise PlatformError(f"{self.task} has no object {unknown[0]!r}: it has {tuple(self.free)}")
        self.object_names = tuple(objects)
        self.geom_object = np.full(self.model.ngeom, -1, dtype=np.int64)  # geom id → index of the object
        for k, name in enumerate(objects):
            self.geom_object[self.model.geom_bodyid == self.free[name][0]] = k

    def object_pose(self, name: str) -> np.ndarray:
        """World pose (xyz + quaternion wxyz) of an object's body (its free joint's coordinates)."""
        b = self.free[name][0]
        return np.concatenate([self.data.xpos[b], self.data.xquat[b]])

    def body_rotation(self, name: str) -> np.ndarray:
        return np.array(self.data.xmat[self.free[name][0]]).reshape(3, 3)

    def tcp(self, arm: int) -> tuple[np.ndarray, np.ndarray]:
        """World position and rotation matrix of arm `arm`'s grip point (0 left, 1 right)."""
        s = self.tcp_sites[arm]
        return np.array(self.data.site_xpos[s]), np.array(self.data.site_xmat[s]).reshape(3, 3)

    def _pairs(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.data.ncon
        return np.asarray(self.data.contact.geom1[:n]), np.asarray(self.data.contact.geom2[:n])

    def touching(self, name: str) -> dict[str, bool]:
        """What touches object `name` now: the left / right arm, either (`robot`), the table."""
        g1, g2 = self._pairs()
        mine = self.model.geom_bodyid == self.free[name][0]
        other = np.concatenate([g2[mine[g1]], g1[mine[g2]]])
        arm = self.geom_arm[other]
        return {"left": bool((arm == 0).any()), "right": bool((arm == 1).any()), "robot": bool((arm >= 0).any()),
                "table": bool((other == self.table_geom).any())}

    def pin_touched(self) -> bool:
        """The peg touches the socket's pin (gym-aloha's insertion success)."""
        g1, g2 = self._pairs()
        peg = self.model.geom_bodyid == self.free["peg"][0]
        return bool(((g1 == self.pin_geom) & peg[g2]).any() or ((g2 == self.pin_geom) & peg[g1]).any())

    def contacts(self) -> np.ndarray:
        """(MAX_OBJECTS,) bool: a robot geom touches a geom of recorded object k (pairs compared in either order)."""
        out = np.zeros(MAX_OBJECTS, dtype=bool)
        g1, g2 = self._pairs()
        for a, b in ((g1, g2), (g2, g1)):
            k = self.geom_object[b[(self.geom_label[a] > 0) & (self.geom_object[b] >= 0)]]
            out[k] = True
        return out

    # -- scenes and stepping ----------------------------------------------------------------------
    def _apply(self, action: np.ndarray) -> None:
        a = np.asarray(action, dtype=np.float64)
        c = self.data.ctrl
        for k in range(2):
            g = grip_position(a[7 * k + 6])
            c[8 * k:8 * k + 6], c[8 * k + 6], c[8 * k + 7] = a[7 * k:7 * k + 6], g, -g

    def _settle(self, seed: int, placements: dict[str, np.ndarray] | None) -> None:
        m, d = self.model, self.data
        home = np.concatenate([HOME, [1.0], HOME, [1.0]])
        for k in range(2):
            d.qpos[8 * k:8 * k + 6], d.qpos[8 * k + 6], d.qpos[8 * k + 7] = HOME, 0.057, -0.057
        parked = {name: np.concatenate([park(k), [1, 0, 0, 0]]) for k, name in enumerate((DISTRACTOR, *self.extras))}
        poses = {**parked, **layout(self.spec, seed), **(placements or {})}
        for name, pose in poses.items():
            if name not in self.free:
                raise PlatformError(f"{self.task}: cannot place {name!r}, not a free object of the scene")
            a = self.free[name][1]
            d.qpos[a:a + 7] = pose
            d.qpos[a + 3:a + 7] /= np.linalg.norm(d.qpos[a + 3:a + 7])
        self._apply(home)
        mujoco.mj_forward(m, d)
        for _ in range(SETTLE_STEPS):
            self.step(home, observe=False)

    def reset(self, seed: int, placements: dict[str, np.ndarray] | None = None) -> Observation:
        """Frame 0 of scene `seed` (cached without placements) from a clean MuJoCo data block; `placements`
        (name → world xyz + quaternion wxyz) override the seed's initial poses before settling."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        if placements or seed not in self._scenes:
            self._settle(seed, placements)
            if not placements:
                state = np.zeros(mujoco.mj_stateSize(m, spec))
                mujoco.mj_getState(m, d, state, spec)
                self._scenes[seed] = state
        else:
            mujoco.mj_setState(m, d, self._scenes[seed], spec)
            mujoco.mj_forward(m, d)
        self.start_poses = {name: self.object_pose(name) for name in self.free}
        return self._observe()

    def step(self, action: np.ndarray, observe: bool = True) -> Observation | None:
        self._apply(action)
        mujoco.mj_step(self.model, self.data, nstep=SUBSTEPS)
        mujoco.mj_forward(self.model, self.data)  # positions, contacts and cameras of the state just reached
        return self._observe() if observe else None

    def _observe(self) -> Observation:
        d = self.data
        poses = np.full((MAX_OBJECTS, 7), np.nan, dtype=np.float32)
        for k, name in enumerate(self.object_names):
            poses[k] = self.object_pose(name)
        tcp = np.concatenate([np.concatenate([d.site_xpos[s], quat_wxyz(d.site_xmat[s])]) for s in self.tcp_sites])
        ob = Observation(qpos=np.asarray(d.qpos[QPOS_INDEX], dtype=np.float32), tcp_pose=tcp.astype(np.float32),
                         object_poses=poses, contacts=self.contacts(), success=bool(self.spec.success_test(self)))
        if self.render:
            ob.rgb, ob.mask, ob.objects = self.render_frame()
        return ob

    def render_frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """RGB (240, 320, 3) uint8, robot label mask (240, 320) uint8 of the head camera and the tracked objects'
        label image (240, 320) uint8 (k + 1 where object k is the visible surface, else 0)."""
        r = self._renderer
        if r is None:
            raise PlatformError("the platform was created without a renderer")
        r.update_scene(self.data, camera=self.camera_id)
        rgb = r.render()
        r.enable_segmentation_rendering()
        try:
            seg = r.render()
        finally:
            r.disable_segmentation_rendering()
        geom = (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)) & (seg[..., 0] >= 0)  # int: an enum compares per pixel
        mask = np.zeros(seg.shape[:2], dtype=np.uint8)
        ids = seg[..., 0][geom]
        mask[geom] = self.geom_label[ids]
        labels = np.zeros(seg.shape[:2], dtype=np.uint8)
        labels[geom] = self.geom_object[ids] + 1
        return rgb, mask, labels

    def camera_params(self) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV intrinsics (3, 3) (pixel centres at integers) and world→camera extrinsics (3, 4, m) of the head
        camera; it is fixed in the world, so any state gives the same."""
        m, d, c = self.model, self.data, self.camera_id
        f = 0.5 * HEIGHT / np.tan(np.deg2rad(m.cam_fovy[c]) / 2)
        K = np.array([[f, 0, (WIDTH - 1) / 2], [0, f, (HEIGHT - 1) / 2], [0, 0, 1]], dtype=np.float32)
        R = (d.cam_xmat[c].reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])).T  # MuJoCo → OpenCV axes
        return K, np.concatenate([R, (-R @ d.cam_xpos[c])[:, None]], axis=1).astype(np.float32)

    def ee_action(self, action: np.ndarray) -> np.ndarray:
        """End-effector form of a joint action: per arm the grip point that the 6 joint targets reach by forward
        kinematics (world xyz, m; XYZ Euler, rad) and the unchanged gripper command."""
        fk = self._fk
        fk.qpos[QPOS_INDEX[:12]] = np.asarray(action, dtype=np.float64)[[0, 1, 2, 3, 4, 5, 7, 8, 9, 10, 11, 12]]
        mujoco.mj_kinematics(self.model, fk)
        out = []
        for k, s in enumerate(self.tcp_sites):
            out += [fk.site_xpos[s], euler_xyz(fk.site_xmat[s]), [action[7 * k + 6]]]
        return np.concatenate(out).astype(np.float32)

    def body_positions(self, qpos: np.ndarray, bodies: Sequence[int]) -> np.ndarray:
        """World origins of `bodies` for each row of `qpos` (T, 14; the observation layout) by forward
        kinematics: (T·B, 3)."""
        fk, out = self._fk, []
        for q in np.asarray(qpos, dtype=np.float64):
            fk.qpos[QPOS_INDEX], fk.qpos[[7, 15]] = q, -q[12:]
            mujoco.mj_kinematics(self.model, fk)
            out.append(np.array(fk.xpos[list(bodies)]))
        return np.concatenate(out)

    # -- replay -----------------------------------------------------------------------------------
    def replay(self, seed: int, actions: np.ndarray, placements: dict[str, np.ndarray] | None = None) -> Rollout:
        """Lay out scene `seed` (with `placements`) and execute a (T, 14) joint-target stream, recording every
        frame."""
        actions = checked_stream(actions, ACTION_DIM)
        ro = Rollout(self.task, int(seed), actions, np.stack([self.ee_action(a) for a in actions]))
        ro.observations.append(self.reset(seed, placements))
        if self.render:
            ro.intrinsic, ro.extrinsic = self.camera_params()
        for a in actions:
            ro.observations.append(self.step(a))
        return ro
