"""The build side of the release format: seed ranges, per-frame features, what a platform stores.

The names a reader of a release needs live in `wsp_eval.release_format` and are re-exported here, so builders,
writer, release, tests and the evaluation side agree.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from wsp_eval.release_format import (  # noqa: F401  (re-exported: the build side and tests import them from here)
    BUILD_REPORT, CARD, CODEBASE_VERSION, CONFIG_NAME, CROISSANT, DEFAULT_RELEASE_NAME, EPISODE_COLUMNS, EPISODE_ID,
    CONTACTS_KEY, FPS, IMAGE_SIZE, INSTANCE_ID, INSTANCES, LOG_DIR, MASK_COLUMN, MAX_OBJECTS, OBJECT_POSES_KEY,
    MASKS, OBJECT_MASK_COLUMN, RELEASE_JSON, SOURCE_ROLE, STAGING_DIR, SUITES,
)

# ManiSkill's native streams (spec §2): the platform module imports these, never the reverse.
ACTION_DIM = 8  # 7 arm joint targets + gripper command (1 open … −1 closed)
EE_ACTION_DIM = 7  # TCP target position in the robot base frame, XYZ Euler angles, gripper command

# Disjoint scene-seed ranges: a suite's slot k, attempt a uses base + 100·k + a (a < MAX_ATTEMPTS).
MAX_ATTEMPTS = 100
SEED_BASE = {"train": 0, "t1": 1_000_000, "t2": 2_000_000, "t3": 3_000_000, "t4": 4_000_000, "t5": 5_000_000}
SEED_SPAN = 1_000_000
# The private range (`--seed-range private`): scenes no public release has, chosen by the build seed. Slot k,
# attempt a gets PRIVATE_BASE + (m·(100·k + a) + c) mod PRIVATE_PRIME, where m ≠ 0 and c come from the SHA-256 of
# the build seed: one build never repeats a scene (a bijection mod a prime), and every seed lies above every named
# range (and below 2³¹, with T2's donor offset added).
PRIVATE_RANGE = "private"
PRIVATE_BASE = 10_000_000
PRIVATE_PRIME = 1_000_000_007


def _private_key(build_seed: int) -> tuple[int, int]:
    digest = hashlib.sha256(f"worldsimprobe private scenes {build_seed}".encode()).digest()
    return 1 + int.from_bytes(digest[:8], "big") % (PRIVATE_PRIME - 1), int.from_bytes(digest[8:16], "big") % PRIVATE_PRIME


def scene_seed(suite: str, slot: int, attempt: int, build_seed: int = 0) -> int:
    """Slot `slot`, attempt `attempt`'s scene seed in `suite`'s range (or the private range, keyed by
    `build_seed`)."""
    if not 0 <= attempt < MAX_ATTEMPTS:
        raise ValueError(f"attempt {attempt} outside [0, {MAX_ATTEMPTS})")
    private = suite == PRIVATE_RANGE
    index = MAX_ATTEMPTS * slot + attempt
    if index >= (PRIVATE_PRIME if private else SEED_SPAN):
        raise ValueError(f"slot {slot} exceeds the {suite} seed range")
    if not private:
        return SEED_BASE[suite] + index
    if build_seed == 0:
        raise ValueError("the private seed range needs a build seed other than 0 (--seed): it keys the scenes")
    m, c = _private_key(build_seed)
    return PRIVATE_BASE + (m * index + c) % PRIVATE_PRIME


def slot_attempt(suite: str, seed: int, build_seed: int = 0) -> tuple[int, int]:
    """The inverse of `scene_seed`: which slot and attempt drew `seed`."""
    if suite == PRIVATE_RANGE:
        m, c = _private_key(build_seed)
        index = (seed - PRIVATE_BASE - c) * pow(m, -1, PRIVATE_PRIME) % PRIVATE_PRIME
    else:
        index = seed - SEED_BASE[suite]
    return divmod(index, MAX_ATTEMPTS)


# -- per-frame features (LeRobot) ---------------------------------------------------------------------
VIDEO_KEY = "observation.images.base_camera"  # ManiSkill's; a platform's own is `kit(p).info.video_key`


def frame_features(info: PlatformInfo) -> dict:
    """LeRobot feature spec of every rollout frame on the platform `info` describes. Frame t holds the
    observation at t and the action applied after it; the last frame's action repeats the previous one and is
    never executed. `action` is the platform's native stream; the other stream (`alt_action_key`) is stored
    beside it. Policy inputs (`observation.*`: the camera, joint state, end-effector pose) hold no padding and
    no NaN; simulator ground truth is under `sim.*` and the label masks in MASKS, outside the features."""
    img = (info.height, info.width, 3)
    hwc = ["height", "width", "channels"]
    return {
        info.video_key: {"dtype": "video", "shape": img, "names": hwc},
        "observation.state": {"dtype": "float32", "shape": (len(info.state_names),), "names": list(info.state_names)},
        "observation.ee_pose": {"dtype": "float32", "shape": (len(info.ee_names),), "names": list(info.ee_names)},
        OBJECT_POSES_KEY: {"dtype": "float32", "shape": (MAX_OBJECTS * 7,), "names": None},
        CONTACTS_KEY: {"dtype": "float32", "shape": (MAX_OBJECTS,), "names": None},
        "action": {"dtype": "float32", "shape": (len(info.action_names),), "names": list(info.action_names)},
        info.alt_action_key: {"dtype": "float32", "shape": (len(info.alt_action_names),),
                              "names": list(info.alt_action_names)},
        "next.success": {"dtype": "bool", "shape": (1,), "names": None},
    }


PANDA_STATE = tuple(f"q{i}" for i in range(7)) + ("finger_l", "finger_r")  # 7 arm joints (rad) + 2 fingers (m)
EE_POSE = ("x", "y", "z", "qw", "qx", "qy", "qz")  # world position (m) + quaternion


@dataclass(frozen=True)
class PlatformInfo:
    """What a reader of a release needs to know about a platform (spec §2). `width` × `height`: the camera's
    frames (px); `state_names` / `ee_names`: the columns of `observation.state` (arm joints first) and
    `observation.ee_pose` (per arm, xyz + quaternion wxyz); `state_text`: the state in words (the card)."""

    name: str
    fps: int
    width: int
    height: int
    camera: str
    robot_type: str
    action_space: str  # the native stream, column `action`
    action_names: tuple[str, ...]
    alt_action_key: str  # the other stream stored beside it
    alt_action_space: str
    alt_action_names: tuple[str, ...]
    simulator: str
    state_names: tuple[str, ...] = PANDA_STATE
    ee_names: tuple[str, ...] = EE_POSE
    state_text: str = "robot joint positions (7 arm + 2 fingers)"

    def __post_init__(self):
        if self.width <= 0 or self.height <= 0 or self.fps <= 0:
            raise ValueError(f"platform {self.name!r}: width, height and fps must be positive")
        if len(self.ee_names) % 7:
            raise ValueError(f"platform {self.name!r}: ee_names must hold xyz + quaternion per arm (7 each)")

    @property
    def video_key(self) -> str:
        return f"observation.images.{self.camera}"


_JOINTS = PANDA_STATE[:7]
_EE_DELTA = ("dx", "dy", "dz", "drx", "dry", "drz", "gripper")
PLATFORM_INFO = {
    "maniskill": PlatformInfo(
        "maniskill", FPS, IMAGE_SIZE, IMAGE_SIZE, "base_camera", "panda",
        "pd_joint_pos: 7 joint position targets (rad) + gripper (1 open … -1 closed)", _JOINTS + ("gripper",),
        "action.ee", "TCP target in the robot base frame (m), XYZ Euler angles (rad), gripper (forward kinematics of "
        "the joint targets)", ("x", "y", "z", "rx", "ry", "rz", "gripper"), "ManiSkill 3.0.1 on SAPIEN 3.0.3"),
    "libero": PlatformInfo(
        "libero", FPS, IMAGE_SIZE, IMAGE_SIZE, "agentview", "panda",
        "OSC_POSE deltas in [-1, 1]: end-effector position (x0.05 m), axis-angle rotation (x0.5 rad), gripper "
        "(-1 open ... 1 closed)", _EE_DELTA,
        "action.joint", "the 7 joint positions (rad) each action reached + the gripper command", _JOINTS + ("gripper",),
        "LIBERO (hf-libero 0.1.4) on robosuite 1.4.0 / MuJoCo 3.8"),
}
