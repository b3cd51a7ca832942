"""ManiSkill3 (SAPIEN, CPU physics) platform: replays 8-D `pd_joint_pos` streams and records everything a
rollout stores — the 128×128 `base_camera` RGB, an exact robot label mask from SAPIEN segmentation, robot
qpos, TCP pose, task object poses, robot–object contact flags, camera parameters and task success.

One `ManiSkillPlatform` holds one long-lived env (the first rendering env in a process costs seconds;
`reset(seed=…)` costs ~0.2 s). `render=False` gives a state-only env (~40× cheaper per step) for
validating proposals before anything is rendered.
"""

from __future__ import annotations

import contextlib
import io
import logging
from dataclasses import dataclass

import numpy as np

from wsp_data.platforms import Observation, PlatformError, Rollout, checked_stream
from wsp_data.platforms.maniskill.runtime import configure_cpu_rendering
from wsp_data.schema import ACTION_DIM, IMAGE_SIZE, MAX_OBJECTS

configure_cpu_rendering()

import mani_skill.envs  # noqa: E402,F401  (registers the tasks)
import sapien  # noqa: E402
import sapien.physx as physx  # noqa: E402
import torch  # noqa: E402
from mani_skill.utils.registration import REGISTERED_ENVS  # noqa: E402
from mani_skill.utils.structs import Pose  # noqa: E402
from mani_skill.utils.geometry import rotation_conversions  # noqa: E402
from mani_skill.utils.structs import Actor, Link  # noqa: E402

logging.getLogger("mani_skill").setLevel(logging.ERROR)

CAMERA = "base_camera"
MASK_ARM, MASK_DISTAL = 1, 2
# Links labelled 2 ("wrist, hand and fingers": the T4 motion gate seeds on these); every other robot link is 1.
DISTAL_LINKS = frozenset({
    "panda_link7", "panda_link8", "panda_hand", "panda_hand_tcp", "panda_leftfinger", "panda_rightfinger",
    "panda_leftfinger_pad", "panda_rightfinger_pad", "camera_link", "camera_mount",
})
GRIPPER_OPEN, GRIPPER_CLOSED = 1.0, -1.0


@dataclass(frozen=True)
class ExtraActor:
    """A rigid primitive added to a task's scene by the scene loader (a ManiSkill scene hook), so existing
    segmentation ids do not change. It starts parked out of view behind the camera; `reset(...,
    placements={name: pose})` puts it into the scene for an episode."""

    name: str
    shape: str  # "box" (half_size = half extents) or "sphere" (half_size[0] = radius)
    half_size: tuple[float, float, float]
    color: tuple[float, float, float, float] = (0.15, 0.35, 0.85, 1.0)
    density: float = 1000.0
    # PhysX puts a body whose kinetic energy stays below its sleep threshold (ManiSkill: 0.005) to sleep and
    # zeroes its velocity: a tapped ball rolling at 0.2 m/s froze after ~5 cm (measured). Props that must
    # roll or topple on their own set sleeps=False.
    sleeps: bool = True

    def add_to(self, builder) -> None:
        material = sapien.render.RenderMaterial(base_color=list(self.color))
        if self.shape == "box":
            builder.add_box_collision(half_size=self.half_size, density=self.density)
            builder.add_box_visual(half_size=self.half_size, material=material)
        elif self.shape == "sphere":
            builder.add_sphere_collision(radius=self.half_size[0], density=self.density)
            builder.add_sphere_visual(radius=self.half_size[0], material=material)
        else:
            raise PlatformError(f"unsupported extra actor shape {self.shape!r}")


PARKING = np.array([2.0, 2.0, 0.0])  # behind the base camera, off the table


def _env_class(env_id: str, extras: tuple[ExtraActor, ...]):
    """The task's env class, or a subclass whose scene loader also builds `extras`."""
    base = REGISTERED_ENVS[env_id].cls
    if not extras:
        return base

    class SceneWithExtras(base):
        def _load_scene(self, options: dict):
            super()._load_scene(options)
            for i, extra in enumerate(extras):
                builder = self.scene.create_actor_builder()
                extra.add_to(builder)
                builder.initial_pose = sapien.Pose(PARKING + [0.5 * i, 0, extra.half_size[2]])
                setattr(self, extra.name, builder.build(name=extra.name))

    SceneWithExtras.__name__ = f"{base.__name__}WithExtras"
    return SceneWithExtras


def to_numpy(x) -> np.ndarray:
    """A torch tensor (any device) or array-like as a numpy array."""
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


def euler_xyz(q) -> np.ndarray:
    """A quaternion (wxyz) as the XYZ Euler angles `pd_ee_pose` takes for its target orientation."""
    rot = rotation_conversions.quaternion_to_matrix(torch.as_tensor(np.asarray(q), dtype=torch.float64))
    return to_numpy(rotation_conversions.matrix_to_euler_angles(rot, "XYZ"))


class ManiSkillPlatform:
    """One ManiSkill env for one task, kept alive across many rollouts."""

    def __init__(self, task: str, *, render: bool = True, control_mode: str = "pd_joint_pos",
                 objects: tuple[str, ...] = (), extras: tuple[ExtraActor, ...] = ()):
        self.task, self.render, self.control_mode = task, render, control_mode
        env_id = task if task.endswith("-v1") else f"{task}-v1"
        if env_id not in REGISTERED_ENVS:
            raise PlatformError(f"unknown ManiSkill task {task!r}")
        with contextlib.redirect_stdout(io.StringIO()):  # ManiSkill's own `make` instantiates the class
            self.env = _env_class(env_id, tuple(extras))(
                obs_mode="rgb+segmentation" if render else "state_dict", sim_backend="physx_cpu",
                render_backend="cpu", control_mode=control_mode, num_envs=1,
                sensor_configs=dict(width=IMAGE_SIZE, height=IMAGE_SIZE),
            )
        self.u = self.env.unwrapped
        self._prune_sensors()
        self.object_names = objects
        self._awake = tuple(e.name for e in extras if not e.sleeps)
        self._luts: tuple[np.ndarray, np.ndarray] | None = None
        self._pin = None

    # -- lifecycle ------------------------------------------------------------------------------
    def close(self) -> None:
        self.env.close()

    def __enter__(self) -> ManiSkillPlatform:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- scene facts ------------------------------------------------------------------------------
    @property
    def robot(self):
        return self.u.agent.robot

    @property
    def qlimits(self) -> np.ndarray:
        """(9, 2) lower/upper limits of the 7 arm and 2 finger joints."""
        return to_numpy(self.robot.get_qlimits()[0])

    def actor(self, name: str) -> Actor:
        a = getattr(self.u, name, None)
        if not isinstance(a, Actor):
            raise PlatformError(f"{self.task} has no actor {name!r}")
        return a

    def _label_luts(self) -> tuple[np.ndarray, np.ndarray]:
        """Segmentation id → robot label (0 / 1 / 2) and → object label (k + 1 for tracked object k, else 0),
        built once per scene from the env's id map."""
        size = max(self.u.segmentation_id_map) + 1
        robot_lut, object_lut = np.zeros(size, dtype=np.uint8), np.zeros(size, dtype=np.uint8)
        robot = self.robot
        for sid, obj in self.u.segmentation_id_map.items():
            if isinstance(obj, Link) and obj.articulation is robot:
                robot_lut[sid] = MASK_DISTAL if obj.name in DISTAL_LINKS else MASK_ARM
        for k, name in enumerate(self.object_names):
            object_lut[self.actor(name)._objs[0].per_scene_id] = k + 1
        return robot_lut, object_lut

    # -- stepping ---------------------------------------------------------------------------------
    def _prune_sensors(self) -> None:
        """Render only the evaluated camera: a task's hand camera would double the cost of every step."""
        for name in list(self.u._sensors):
            if name != CAMERA:
                del self.u._sensors[name]

    def reset(self, seed: int, placements: dict[str, np.ndarray] | None = None) -> Observation:
        """Rebuild the scene and reset it to `seed`, then move actors to `placements` (name → world pose
        xyz + quaternion wxyz, at rest). A plain reset keeps PhysX state from earlier episodes (measured:
        the same stream replayed after another episode drifts by 5e-4 rad); rebuilding (~0.2 s) makes every
        rollout independent of the env's history, so shards, workers and resumed builds agree."""
        obs, _ = self.env.reset(seed=int(seed), options={"reconfigure": True})
        self._prune_sensors()
        self._luts = None  # segmentation ids are re-read from the rebuilt scene
        for name in self._awake:
            self.actor(name)._objs[0].find_component_by_type(physx.PhysxRigidDynamicComponent).set_sleep_threshold(0.0)
        if placements:
            for name, pose in placements.items():
                pose = torch.as_tensor(np.asarray(pose, dtype=np.float32))[None]
                actor = self.actor(name)
                actor.set_pose(Pose.create_from_pq(pose[:, :3], pose[:, 3:]))
                actor.set_linear_velocity(torch.zeros(1, 3))
                actor.set_angular_velocity(torch.zeros(1, 3))
            obs = self.u.get_obs()
        return self._observe(obs)

    def step(self, action: np.ndarray) -> Observation:
        obs, _, _, _, _ = self.env.step(torch.as_tensor(np.asarray(action, dtype=np.float32))[None])
        return self._observe(obs)

    def _observe(self, obs) -> Observation:
        u = self.u
        poses = np.full((MAX_OBJECTS, 7), np.nan, dtype=np.float32)
        contacts = np.zeros(MAX_OBJECTS, dtype=bool)
        for i, name in enumerate(self.object_names):
            a = self.actor(name)
            poses[i] = to_numpy(a.pose.raw_pose[0])
            contacts[i] = self.robot_touches(a)
        ob = Observation(
            qpos=to_numpy(self.robot.get_qpos()[0]).astype(np.float32),
            tcp_pose=to_numpy(u.agent.tcp.pose.raw_pose[0]).astype(np.float32),
            object_poses=poses, contacts=contacts, success=bool(to_numpy(u.evaluate()["success"]).reshape(-1)[0]),
        )
        if self.render:
            cam = obs["sensor_data"][CAMERA]
            ob.rgb = to_numpy(cam["rgb"][0]).astype(np.uint8)
            if self._luts is None:
                self._luts = self._label_luts()
            robot_lut, object_lut = self._luts
            seg = np.clip(to_numpy(cam["segmentation"][0, ..., 0]).astype(np.int64), 0, len(robot_lut) - 1)
            ob.mask, ob.objects = robot_lut[seg], object_lut[seg]
        return ob

    def robot_touches(self, actor: Actor) -> bool:
        """True when any robot link has a nonzero contact impulse with the actor this step."""
        scene = self.u.scene
        for link in self.robot.get_links():
            if float(torch.linalg.norm(scene.get_pairwise_contact_impulses(link, actor))) > 0:
                return True
        return False

    def camera_params(self) -> tuple[np.ndarray, np.ndarray]:
        cam = self.u.scene.sensors[CAMERA]
        p = cam.get_params()
        return to_numpy(p["intrinsic_cv"][0]).astype(np.float32), to_numpy(p["extrinsic_cv"][0]).astype(np.float32)

    # -- kinematics -------------------------------------------------------------------------------
    def ee_action(self, joint_action: np.ndarray) -> np.ndarray:
        """The end-effector form of a joint action: TCP target in the robot base frame (xyz + XYZ Euler)
        by forward kinematics of the 7 joint targets, plus the unchanged gripper command."""
        if self._pin is None:
            art = self.robot._objs[0]
            self._pin = art.create_pinocchio_model()
            self._tcp_index = self.u.agent.tcp._objs[0].get_index()
        q = np.zeros(self.robot.get_qpos().shape[1])
        q[:7] = joint_action[:7]
        self._pin.compute_forward_kinematics(q)
        pose = self._pin.get_link_pose(self._tcp_index)  # relative to the articulation root (robot base)
        return np.array([*pose.p, *euler_xyz(pose.q), joint_action[7]], dtype=np.float32)

    # -- replay -----------------------------------------------------------------------------------
    def replay(self, seed: int, actions: np.ndarray, placements: dict[str, np.ndarray] | None = None) -> Rollout:
        """Reset to `seed` (and `placements`) and execute a (T, 8) `pd_joint_pos` stream, recording every frame."""
        actions = checked_stream(actions, ACTION_DIM)
        if self.control_mode != "pd_joint_pos":
            raise PlatformError("replay needs a pd_joint_pos platform")
        ro = Rollout(self.task, int(seed), actions, np.stack([self.ee_action(a) for a in actions]))
        ro.observations.append(self.reset(seed, placements))
        if self.render:
            ro.intrinsic, ro.extrinsic = self.camera_params()
        for a in actions:
            ro.observations.append(self.step(a))
        return ro
