"""The release format: path templates, per-frame features, episode columns, seed ranges.

Every constant a reader of a release needs lives here, so builders, writer, release and tests agree.
"""

from __future__ import annotations

from dataclasses import dataclass

# ManiSkill platform constants (SPEC §2): the platform module imports these, never the reverse, so that
# readers of a release (wsp_eval) never import a simulator.
FPS = 20
IMAGE_SIZE = 128
ACTION_DIM = 8  # 7 arm joint targets + gripper command (1 open … −1 closed)
EE_ACTION_DIM = 7  # TCP target position in the robot base frame, XYZ Euler angles, gripper command
MAX_OBJECTS = 4  # object pose / contact columns per frame (unused slots are NaN / False)

DEFAULT_RELEASE_NAME = "worldsimprobe"
CODEBASE_VERSION = "v3.0"  # LeRobot dataset format

# -- release layout ---------------------------------------------------------------------------------
RELEASE_JSON = "release.json"
CARD = "README.md"
CROISSANT = "croissant.json"
INSTANCES = "instances.parquet"
BUILD_REPORT = "build_report.json"  # per config, beside instances.parquet
STAGING_DIR = ".wsp-staging"  # per config, under the release; removed once the config is assembled
CONFIG_NAME = "{suite}_{platform}"  # e.g. t1_maniskill
EPISODE_ID = "episode_{index:06d}"  # submission path component: <config>/<episode_id>/seed<k>.mp4
INSTANCE_ID = "{config}/{slot:06d}"

SUITES = ("t1", "t2", "t3", "t4", "t5", "train")
PLATFORMS = ("maniskill", "libero")

# Disjoint scene-seed ranges: a suite's slot k, attempt a uses base + 100·k + a (a < MAX_ATTEMPTS).
MAX_ATTEMPTS = 100
SEED_BASE = {"train": 0, "t1": 1_000_000, "t2": 2_000_000, "t3": 3_000_000, "t4": 4_000_000, "t5": 5_000_000}
SEED_SPAN = 1_000_000


def scene_seed(suite: str, slot: int, attempt: int) -> int:
    if not 0 <= attempt < MAX_ATTEMPTS:
        raise ValueError(f"attempt {attempt} outside [0, {MAX_ATTEMPTS})")
    seed = SEED_BASE[suite] + MAX_ATTEMPTS * slot + attempt
    if seed >= SEED_BASE[suite] + SEED_SPAN:
        raise ValueError(f"slot {slot} exceeds the {suite} seed range")
    return seed


# -- per-frame features (LeRobot) ---------------------------------------------------------------------
VIDEO_KEY = "observation.images.base_camera"  # ManiSkill's; a platform's own is `PLATFORM_INFO[p].video_key`
MASK_KEY = "observation.robot_mask"


def frame_features(platform: str = "maniskill") -> dict:
    """LeRobot feature spec of every rollout frame on `platform`. Frame t holds the observation at t and the
    action applied after it; the last frame's action repeats the previous one and is never executed.
    `action` is the platform's native stream; the other stream (`alt_action_key`) is stored beside it."""
    info = PLATFORM_INFO[platform]
    img = (IMAGE_SIZE, IMAGE_SIZE, 3)
    hwc = ["height", "width", "channels"]
    return {
        info.video_key: {"dtype": "video", "shape": img, "names": hwc},
        # label image, the label in all three channels: 0 not robot, 1 arm, 2 wrist/hand/fingers
        MASK_KEY: {"dtype": "image", "shape": img, "names": hwc},
        "observation.state": {"dtype": "float32", "shape": (9,), "names": [f"q{i}" for i in range(7)] + ["finger_l", "finger_r"]},
        "observation.ee_pose": {"dtype": "float32", "shape": (7,), "names": ["x", "y", "z", "qw", "qx", "qy", "qz"]},
        "observation.object_poses": {"dtype": "float32", "shape": (MAX_OBJECTS * 7,), "names": None},
        "observation.contacts": {"dtype": "bool", "shape": (MAX_OBJECTS,), "names": None},
        "action": {"dtype": "float32", "shape": (len(info.action_names),), "names": list(info.action_names)},
        info.alt_action_key: {"dtype": "float32", "shape": (len(info.alt_action_names),),
                              "names": list(info.alt_action_names)},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    }


# Episode-level columns appended to LeRobot's meta/episodes table (readable as ds.meta.episodes[i][...]).
SOURCE_ROLE = "source"  # an instance's unscored, unperturbed source rollout (action-blind baseline, paired training data)

EPISODE_COLUMNS = (
    "wsp.episode_id", "wsp.instance_id", "wsp.suite", "wsp.platform", "wsp.task", "wsp.seed", "wsp.role",
    "wsp.source", "wsp.intervention", "wsp.objects", "wsp.camera_intrinsic", "wsp.camera_extrinsic",
    "wsp.success", "wsp.num_frames",
)


@dataclass(frozen=True)
class PlatformInfo:
    """What a reader of a release needs to know about a platform (SPEC §2)."""

    name: str
    fps: int
    image_size: int
    camera: str
    robot_type: str
    action_space: str  # the native stream, column `action`
    action_names: tuple[str, ...]
    alt_action_key: str  # the other stream stored beside it
    alt_action_space: str
    alt_action_names: tuple[str, ...]
    simulator: str

    @property
    def video_key(self) -> str:
        return f"observation.images.{self.camera}"


_JOINTS = tuple(f"q{i}" for i in range(7))
_EE_DELTA = ("dx", "dy", "dz", "drx", "dry", "drz", "gripper")
PLATFORM_INFO = {
    "maniskill": PlatformInfo(
        "maniskill", FPS, IMAGE_SIZE, "base_camera", "panda",
        "pd_joint_pos: 7 joint position targets (rad) + gripper (1 open … -1 closed)", _JOINTS + ("gripper",),
        "action.ee", "TCP target in the robot base frame (m), XYZ Euler angles (rad), gripper (forward kinematics of "
        "the joint targets)", ("x", "y", "z", "rx", "ry", "rz", "gripper"), "ManiSkill 3.0.1 on SAPIEN 3.0.3"),
    "libero": PlatformInfo(
        "libero", FPS, IMAGE_SIZE, "agentview", "panda",
        "OSC_POSE deltas in [-1, 1]: end-effector position (x0.05 m), axis-angle rotation (x0.5 rad), gripper "
        "(-1 open ... 1 closed)", _EE_DELTA,
        "action.joint", "the 7 joint positions (rad) each action reached + the gripper command", _JOINTS + ("gripper",),
        "LIBERO (hf-libero 0.1.4) on robosuite 1.4.0 / MuJoCo 3.8"),
}
