"""Simulator-labelled clips for training and validating a T5 judge, from a release's T5 configs (and T4's).

Every clip is what a judge sees (`JUDGE_FRAMES` frames and the frame-0 object position) plus what the
simulator says it shows. Kinds (`Clip.kind`) and their targets (label, agent_ok, object_ok; None = no target):

| kind | frames | label | agent | object |
|---|---|---|---|---|
| `reference` | the T5 reference, sampled as `sample_frames` does | its primitive | True | True |
| `static` | frame 0 repeated | None | False | False |
| `approach` | the reference up to the first contact: the robot moves, the object has not moved | None | None | False |
| `no_robot` | the reference with the robot held at its frame-0 pose (robot mask pixels of frame t replaced by a background estimate, frame 0's robot pasted back): the object moves with no robot near it | None | False | None |
| `frozen` | the reference with the object held at its frame-0 pose: every pixel but frame t's robot is frame 0's scene (where frame 0 shows the robot, the last frame before contact that does not, else inpainted): the robot performs the primitive and nothing responds, as a world model that ignores contact draws it | None | True | False where it visibly differs from the reference (`visibly_different`), else None |
| `erased` | the `frozen` clip, but from first contact on the object fades out where it stood (its frame-0 footprint, `object_footprint`, blended into an inpainted scene over half the time left): the robot performs the primitive and the object vanishes, as world models often draw it (`Clip.clear`: its reference shows the object visibly away from that footprint) | None | True | False where it visibly differs from the reference, else None |
| `t4` | a T4 reference (distractor, false contact, spatial proximity: the evaluated object never moves) | None | None | False |
| `expert` | the instance's source rollout where the task's expert performs one primitive (`EXPERT_PRIMITIVE`: ManiSkill's PushCube pushes, PullCube pulls the cube ≈ 15 cm to its goal): a primitive as the task's expert does it, not as T5 scripts it | that primitive | True | True |

`dense` keeps `DENSE` frames sampled uniformly (so training can jitter the 12 it takes); `judge_frames`
takes the 12 a judge sees.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq

from wsp_eval.backends.judge import JUDGE_FRAMES, frame_indices
from wsp_eval.reference import reference_frames
from wsp_eval.release_format import INSTANCES, split_config
from wsp_eval.suites.reference import InstanceReference
from wsp_eval.tracking import frame_size, frame_xy

DENSE = 2 * JUDGE_FRAMES
T5_KINDS = ("reference", "static", "approach", "no_robot", "frozen")  # `t5_clips`' default; `expert`, `erased` on request
EXPERT_PRIMITIVE = {"PushCube": "push", "PullCube": "pull"}  # tasks whose expert rollout is one primitive
MIN_APPROACH = 6  # frames before first contact needed for an approach clip
VISIBLE_LEVELS = 40  # grey levels (any channel) a pixel must change by to count as visibly changed
VISIBLE_AREA = 9e-4  # fraction of the frame that must change in some frame: ≈ 15 px at 128², 69 at 320×240.
#   Measured on 64 fresh ManiSkill T5 references: frozen rotates change 1–8·10⁻⁴ of the frame (a 6° yaw of a
#   cube 4–8 px wide), every other primitive 10–143·10⁻⁴ but one drop (2·10⁻⁴); a clip below it cannot be told
#   from its reference by eye either, so it is no negative.
FOOTPRINT_RADIUS = 0.12  # of the frame's smaller side: how far from its frame-0 position the object's footprint is
#   looked for (15 px at 128², where ManiSkill's cubes are 4–8 px wide; 29 px at ALOHA's 320×240)


@dataclass
class Clip:
    kind: str
    config: str
    instance_id: str
    task: str
    seed: int
    dense: np.ndarray = field(repr=False)  # (DENSE, H, W, 3) uint8
    object_px: tuple[float, float]  # frame-0 (x, y) in the 256² scoring frame
    label: str | None
    agent: bool | None
    object: bool | None
    primitive: str | None = None  # the T5 instance's intended primitive, whatever the kind (T4: its kind)
    clear: bool | None = None  # `erased` only: the reference shows the object visibly away from where it stood

    def judge_frames(self) -> np.ndarray:
        return self.dense[frame_indices(len(self.dense), JUDGE_FRAMES)]

    @property
    def platform(self) -> str:
        """The config's platform (`t5_aloha` → `aloha`): which of the judge's weights judge this clip."""
        return split_config(self.config)[1]


def _dense(frames: np.ndarray) -> np.ndarray:
    return np.asarray(frames)[frame_indices(len(frames), DENSE)]


def without_robot(frames: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """The clip with the robot held at its frame-0 pose: robot pixels of each frame replaced by a background
    estimate (frame 0, or the last frame where frame 0 shows the robot), then frame 0's robot pasted back."""
    robot = masks > 0
    background = frames[0].copy()
    hole = robot[0] & ~robot[-1]
    background[hole] = frames[-1][hole]
    out = frames.copy()
    for t in range(len(frames)):
        out[t][robot[t]] = background[robot[t]]
        out[t][robot[0]] = frames[0][robot[0]]
    return out


def still_scene(frames: np.ndarray, masks: np.ndarray, contact: int) -> np.ndarray:
    """Frame 0 without the robot: where frame 0 shows the robot, the last frame before `contact` (the first step
    the robot touches the object: nothing has moved yet) that does not, else inpainted."""
    robot = masks > 0
    scene = frames[0].copy()
    hole = robot[0].copy()
    for t in range(min(contact, len(frames)) - 1, 0, -1):
        if not hole.any():
            break
        seen = hole & ~robot[t]
        scene[seen] = frames[t][seen]
        hole &= ~seen
    if hole.any():
        scene = cv2.inpaint(scene, hole.astype(np.uint8), 3, cv2.INPAINT_TELEA)
    return scene


def frozen_object(frames: np.ndarray, masks: np.ndarray, contact: int, idx: np.ndarray) -> np.ndarray:
    """Frames `idx` of the clip with everything but the robot held at frame 0: the robot pixels of frame t over
    `still_scene`."""
    robot = masks > 0
    out = np.repeat(still_scene(frames, masks, contact)[None], len(idx), axis=0)
    for k, t in enumerate(idx):
        out[k][robot[t]] = frames[t][robot[t]]
    return out


def object_footprint(frames: np.ndarray, masks: np.ndarray, object_xy: tuple[float, float]) -> np.ndarray | None:
    """The pixels the object covers at frame 0 (with those it passes over near there), from the reference alone:
    the pixels that some later frame changes visibly (`VISIBLE_LEVELS`) with the robot in neither frame, within
    `FOOTPRINT_RADIUS` of the object's frame-0 position `object_xy` (frame pixels), in connected regions reaching
    within a third of that radius of it; their convex hull, grown by one pixel. None where nothing changed there
    (an object that never left its own pixels: a rotate in place, mostly)."""
    robot = masks > 0
    first = frames[0].astype(np.int16)
    changed = np.zeros(frames.shape[1:3], bool)
    for t in range(1, len(frames)):
        changed |= (np.abs(frames[t].astype(np.int16) - first).max(axis=-1) > VISIBLE_LEVELS) & ~robot[t]
    changed &= ~robot[0]
    h, w = changed.shape
    radius = FOOTPRINT_RADIUS * min(h, w)
    yy, xx = np.mgrid[:h, :w]
    dist = np.hypot(xx - object_xy[0], yy - object_xy[1])
    _, regions = cv2.connectedComponents((changed & (dist <= radius)).astype(np.uint8), connectivity=8)
    keep = np.unique(regions[(regions > 0) & (dist <= radius / 3)])
    if not len(keep):
        return None
    ys, xs = np.nonzero(np.isin(regions, keep))
    hull = cv2.convexHull(np.stack([xs, ys], axis=1).astype(np.int32))
    footprint = cv2.fillConvexPoly(np.zeros((h, w), np.uint8), hull, 1)
    return cv2.dilate(footprint, np.ones((3, 3), np.uint8)) > 0


def erased_object(frames: np.ndarray, masks: np.ndarray, contact: int, idx: np.ndarray,
                  footprint: np.ndarray) -> np.ndarray:
    """Frames `idx` of the `frozen` clip in which, from `contact` on, the object's `footprint` fades into an
    inpainted scene (linearly, gone after half the time left): the robot acts and the object vanishes in place."""
    robot = masks > 0
    scene = still_scene(frames, masks, contact).astype(np.float32)
    gone = cv2.inpaint(scene.astype(np.uint8), footprint.astype(np.uint8), 3, cv2.INPAINT_TELEA).astype(np.float32)
    span = max(1.0, (len(frames) - contact) / 2)
    out = np.empty((len(idx), *frames.shape[1:]), np.uint8)
    for k, t in enumerate(idx):
        a = min(max((t - contact) / span, 0.0), 1.0)
        out[k] = np.round((1 - a) * scene + a * gone).astype(np.uint8)
        out[k][robot[t]] = frames[t][robot[t]]
    return out


def visibly_different(a: np.ndarray, b: np.ndarray, where: np.ndarray | None = None) -> bool:
    """Whether two clips (T, H, W, 3) differ visibly: in some frame at least `VISIBLE_AREA` of the frame's pixels
    (counting only those of the (H, W) mask `where`, if given) differ by more than `VISIBLE_LEVELS` in some channel."""
    changed = (np.abs(a.astype(np.int16) - b.astype(np.int16)).max(axis=-1) > VISIBLE_LEVELS)
    if where is not None:
        changed &= where
    return bool(changed.reshape(len(a), -1).sum(axis=1).max() >= VISIBLE_AREA * a.shape[1] * a.shape[2])


def t5_clips(release: Path, config: str, kinds: tuple[str, ...] = T5_KINDS, limit: int | None = None) -> list[Clip]:
    """The clips of every instance of a T5 config."""
    config_dir = Path(release) / config
    rows = pq.read_table(config_dir / INSTANCES).to_pylist()[:limit]
    out = []
    for row in rows:
        ref = InstanceReference(config_dir, row)
        frames = ref.frames("reference")
        px = (float(row["object_pixel_256"][0]), float(row["object_pixel_256"][1]))
        base = dict(config=config, instance_id=row["instance_id"], task=row["task"], seed=int(row["seed"]),
                    object_px=px, primitive=row["primitive"])
        if "reference" in kinds:
            out.append(Clip("reference", dense=_dense(frames), label=row["primitive"], agent=True, object=True,
                            **base))
        if "static" in kinds:
            out.append(Clip("static", dense=np.repeat(frames[:1], DENSE, axis=0), label=None, agent=False,
                            object=False, **base))
        contact = int(row["first_contact_step"])
        if "approach" in kinds and contact >= MIN_APPROACH:
            out.append(Clip("approach", dense=_dense(frames[:contact]), label=None, agent=None, object=False,
                            **base))
        idx = frame_indices(len(frames), DENSE)
        if "no_robot" in kinds:
            dense = without_robot(frames[idx], ref.masks("reference")[idx])
            out.append(Clip("no_robot", dense=dense, label=None, agent=False, object=None, **base))
        if "frozen" in kinds:
            dense = frozen_object(frames, ref.masks("reference"), contact, idx)
            seen = visibly_different(dense, frames[idx])
            out.append(Clip("frozen", dense=dense, label=None, agent=True, object=False if seen else None, **base))
        if "erased" in kinds:
            masks = ref.masks("reference")
            footprint = object_footprint(frames, masks, frame_xy(px, *frame_size(frames[0])))
            if footprint is not None:
                dense = erased_object(frames, masks, contact, idx, footprint)
                seen = visibly_different(dense, frames[idx])
                out.append(Clip("erased", dense=dense, label=None, agent=True, object=False if seen else None,
                                clear=visibly_different(dense, frames[idx], ~footprint), **base))
        primitive = EXPERT_PRIMITIVE.get(row["task"])
        if "expert" in kinds and primitive and row.get("source_episode_index") is not None:
            source = reference_frames(config_dir, int(row["source_episode_index"]))
            out.append(Clip("expert", dense=_dense(source), label=primitive, agent=True, object=True, **base))
    return out


def t4_clips(release: Path, config: str, limit: int | None = None) -> list[Clip]:
    """T4 references: in every kind the evaluated object never moves (the builder checks it from state)."""
    config_dir = Path(release) / config
    out = []
    for row in pq.read_table(config_dir / INSTANCES).to_pylist():
        frames = InstanceReference(config_dir, row).frames("reference")
        out.append(Clip("t4", config=config, instance_id=row["instance_id"], task=row["task"], seed=int(row["seed"]),
                        dense=_dense(frames), object_px=tuple(float(v) for v in row["object_pixel_256"]),
                        label=None, agent=None, object=False, primitive=row["kind"]))
        if limit is not None and len(out) >= limit:
            break
    return out
