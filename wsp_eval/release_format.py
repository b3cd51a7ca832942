"""The release format both sides share: version, file names, path templates, suite keys, per-frame feature
keys, episode columns, and reading `release.json`.

The build side (`wsp_data`) writes releases with these names and the evaluation side reads them; it lives here
so that scoring never imports the build side. Platform facts (camera, action names) are not here: a reader
finds them in a config's `meta/info.json`.
"""

from __future__ import annotations

import json
from pathlib import Path

BENCHMARK_VERSION = "0.3.0"  # the release format: CHANGELOG.md lists what each version changed
CODEBASE_VERSION = "v3.0"  # LeRobot dataset format
DEFAULT_RELEASE_NAME = "worldsimprobe"

# -- files and paths ----------------------------------------------------------------------------------
RELEASE_JSON = "release.json"
CARD = "README.md"
CROISSANT = "croissant.json"
INSTANCES = "instances.parquet"
# Per config: the exact simulator label images of every frame, one row per frame (columns index, episode_index,
# frame_index, robot_mask and object_mask, each a single-channel PNG). robot_mask: 0 not robot, 1 arm,
# 2 wrist/hand/fingers; object_mask: k + 1 where object k of the episode's `wsp.objects` is the visible surface,
# else 0. Kept out of LeRobot's features so that no policy is ever fed a ground-truth mask as a camera.
MASKS = "masks.parquet"
MASK_COLUMN = "robot_mask"
OBJECT_MASK_COLUMN = "object_mask"
BUILD_REPORT = "build_report.json"  # per config, beside instances.parquet
INPUTS_DIR = "inputs"  # per config of an inputs-only release (`wsp export-inputs`): what a model needs, no more
FIRST_FRAME = "inputs/first_frames/{episode_id}.png"  # frame 0 of each scored episode, lossless
INPUT_ACTIONS = "inputs/actions.parquet"  # one row per scored episode: episode_index, episode_id, action columns
INPUTS_ONLY = "inputs_only"  # release.json key, true in an inputs-only release
STAGING_DIR = ".wsp-staging"  # per config, under the release; removed once the config is assembled
LOG_DIR = ".wsp-logs"  # library, simulator and encoder output of builds, under the release; not in release.json
CONFIG_NAME = "{suite}_{platform}"  # e.g. t1_maniskill
EPISODE_ID = "episode_{index:06d}"  # submission path component: <config>/<episode_id>/seed<k>.mp4
INSTANCE_ID = "{config}/{slot:06d}"

SCORED_SUITES = ("t1", "t2", "t3", "t4", "t5")
SUITES = (*SCORED_SUITES, "train")

# -- frames and episodes --------------------------------------------------------------------------------
FPS = 20
IMAGE_SIZE = 128
MAX_OBJECTS = 4  # object pose / contact slots per frame; the episode's `wsp.objects` lists the used ones
# Simulator ground truth per frame, outside LeRobot's `observation.*` namespace (never a policy input): world
# poses of the objects in `wsp.objects` (xyz + quaternion wxyz; a slot with no object in this rollout — unused,
# or an object only the instance's reference adds — is all zeros, which no real pose is: its quaternion has
# norm 0) and robot–object contact flags (1.0 / 0.0; 0 in unused slots).
OBJECT_POSES_KEY = "sim.object_poses"
CONTACTS_KEY = "sim.contacts"

# Episode-level columns appended to LeRobot's meta/episodes table (readable as ds.meta.episodes[i][...]).
SOURCE_ROLE = "source"  # an instance's unscored, unperturbed source rollout (action-blind baseline, paired training data)
EPISODE_COLUMNS = (
    "wsp.episode_id", "wsp.instance_id", "wsp.suite", "wsp.platform", "wsp.task", "wsp.seed", "wsp.role",
    "wsp.source", "wsp.intervention", "wsp.objects", "wsp.camera_intrinsic", "wsp.camera_extrinsic",
    "wsp.success", "wsp.num_frames",
)


class ReleaseError(RuntimeError):
    """A folder that is not (or not yet) a readable WorldSimProbe release."""


def rebuild_command(root: Path, name: str, entry: dict) -> str:
    """The `wsp build` command of config `name` from its `release.json` entry (its recorded build config)."""
    c = entry.get("build_config", {})
    args = [f"--platform {c.get('platform', split_config(name)[1])}", f"--suite {c.get('suite', split_config(name)[0])}"]
    args += [f"--count {c['count']}"] if c.get("count") else []
    args += [f"--tasks {' '.join(c['tasks'])}"] if c.get("tasks") else []
    args += [f"--seed {c['seed']}"] if c.get("seed") else []
    args += [f"--seed-range {c['seed_range']}"] if c.get("seed_range") else []
    args += [f"--primitives {' '.join(c['primitives'])}"] if c.get("primitives") else []
    return f"wsp build {' '.join(args)} --out {Path(root)}"


def rebuild_commands(root: Path, release: dict) -> list[str]:
    """The `wsp build` command of each config of a parsed `release.json`: what rebuilds the release in this
    version's format."""
    return [rebuild_command(root, name, entry) for name, entry in sorted(release.get("configs", {}).items())]


def format_problem(root: Path, release: dict) -> str | None:
    """One line saying why a release's format is not this version's, with the command that rebuilds it; None when it
    is this version's."""
    found = release.get("version")
    if found == BENCHMARK_VERSION:
        return None
    commands = rebuild_commands(root, release)
    how = (f"rebuild it into a new folder: {commands[0]}" + (f" (and {len(commands) - 1} more configs; "
           "release.json records each build)" if len(commands) > 1 else "")) if commands else "rebuild it with `wsp build`"
    return (f"{root}: release format {found!r}, this worldsimprobe reads format {BENCHMARK_VERSION!r} (object masks "
            f"beside the robot masks, which T5 scores against); {how}")


def split_config(config: str) -> tuple[str, str]:
    """A config name's suite and platform (`t5_aloha` → `("t5", "aloha")`)."""
    suite, platform = config.split("_", 1)
    return suite, platform


def load_release(root: Path) -> dict:
    """The parsed `release.json` of `root`, or ReleaseError saying why there is none."""
    path = Path(root) / RELEASE_JSON
    if not path.exists():
        raise ReleaseError(f"{root}: not a WorldSimProbe release (no {RELEASE_JSON})")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ReleaseError(f"{path}: unreadable ({e})") from e
