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
PLATFORMS = ("maniskill",)

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
VIDEO_KEY = "observation.images.base_camera"
MASK_KEY = "observation.robot_mask"


def frame_features() -> dict:
    """LeRobot feature spec of every rollout frame. Frame t holds the observation at t and the action
    applied after it; the last frame's action repeats the previous one and is never executed."""
    img = (IMAGE_SIZE, IMAGE_SIZE, 3)
    hwc = ["height", "width", "channels"]
    return {
        VIDEO_KEY: {"dtype": "video", "shape": img, "names": hwc},
        # label image, the label in all three channels: 0 not robot, 1 arm, 2 wrist/hand/fingers
        MASK_KEY: {"dtype": "image", "shape": img, "names": hwc},
        "observation.state": {"dtype": "float32", "shape": (9,), "names": [f"q{i}" for i in range(7)] + ["finger_l", "finger_r"]},
        "observation.ee_pose": {"dtype": "float32", "shape": (7,), "names": ["x", "y", "z", "qw", "qx", "qy", "qz"]},
        "observation.object_poses": {"dtype": "float32", "shape": (MAX_OBJECTS * 7,), "names": None},
        "observation.contacts": {"dtype": "bool", "shape": (MAX_OBJECTS,), "names": None},
        "action": {"dtype": "float32", "shape": (ACTION_DIM,), "names": [f"q{i}" for i in range(7)] + ["gripper"]},
        "action.ee": {"dtype": "float32", "shape": (EE_ACTION_DIM,), "names": ["x", "y", "z", "rx", "ry", "rz", "gripper"]},
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
    name: str
    fps: int
    image_size: int
    camera: str
    robot_type: str
    action_space: str


PLATFORM_INFO = {
    "maniskill": PlatformInfo("maniskill", FPS, IMAGE_SIZE, "base_camera", "panda",
                              "pd_joint_pos: 7 joint position targets (rad) + gripper (1 open … -1 closed)"),
}
