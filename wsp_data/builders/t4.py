"""T4 Interaction grounding (spec §3.4): validated no-contact rollouts of three kinds, balanced by slot.

- distractor: one primitive from `PALETTE` (built by the scene loader, so segmentation ids of the task stay
  the same) is put where the task's target lay in a same-task donor episode (another seed); the original
  expert actions are replayed. Kept if it is in view, clear of the task objects and of the robot's swept
  region, never contacted nor displaced, and the task still succeeds. Evaluated object: the distractor.
- false_contact: the expert's arm trajectory with the gripper command clamped open (+1) throughout. Kept if
  both fingers stay open and nothing is ever touched (so the target stays put). Evaluated object: the target.
- spatial_proximity: the target is moved, at rest, outside the swept region of the original rollout; the
  same actions are replayed. Kept if it is in view, clear of the other objects, never touched nor displaced.
  Evaluated object: the target.
Every proposal is validated unrendered first (common validity + the kind's rule over the whole rollout);
only then is it rendered, checked again (the evaluated object must be what the camera sees at its projected
centre in frame 0), encoded as the release stores it, and tracked with `wsp_eval.tracking` on the decoded frames,
the pictures the scorer reads (`wsp_data.episode_codec.stored_video`): the reference gate must reach
`GATE_MIN_REFERENCE`, the object must be trackable, and the reference must score 100. A false-contact instance
must also be one T4 can fail: its source rollout (the expert carrying the target away along the same arm path,
from the same first frame), scored as a submission, must score 0 wherever the simulator moved the target more
than `MOTION_MAX` px.
Thresholds and task choices are documented in docs/suites/t4.md. Which tasks serve which kind, and how a scene is
edited (what a distractor is, where objects may go), is the platform's: `PlatformKit.t4_kind_tasks` and
`t4_rig` (on LIBERO a BDDL scene cannot gain a body, so the distractor is one of the scene's own movable
objects the task does not use, relocated; docs/platforms/libero.md). What the rig hands back (`Proposal`,
`Sight`) and the margins, geometry and false-contact proposal the platforms share are in
`wsp_data.platforms.contract`.
"""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import BuildConfig, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache
from wsp_data.builders.source_survey import SourceSurvey
from wsp_data.episode_codec import stored_video
from wsp_data.platforms.contract import KINDS, Dropped, Proposal, T4Rig
from wsp_data.platforms.interface import Rollout
from wsp_data.schema import SOURCE_ROLE
from wsp_data.staging import RolloutArrays
from wsp_eval.tracking import (
    GATE_MIN_REFERENCE, MOTION_MAX, frame_size, frame_xy, motion_gate, object_motion, project, scoring_video, t4_score,
)

POS_TOL = 0.005  # m: an object that never strays this far from its frame-0 position "stays put"
ROT_TOL = 0.05  # rad: … and never turns this far
MIN_TEXTURED = 5  # of the 9 query points must carry texture at frame 0
MIN_VISIBLE = 0.5  # fraction of reference frames in which the evaluated object must be tracked
REFERENCE_D_MAX = MOTION_MAX / 2  # px: the reference's own d must leave a faithful generation this much headroom
CENTRE_SIGHT_MAX = 1.5  # native px: the evaluated object's nearest visible pixel lies at most this far from its
#   projected centre at frame 0 (the centre's own pixel or a neighbour, diagonals included). Beyond it the query
#   grid sits on whatever hides the object (a LIBERO milk carton behind the juice carton: docs/validity.md, T4 tracker)


def static(poses: np.ndarray) -> bool:
    """(T, 7) poses never leave frame 0's by POS_TOL (m) or ROT_TOL (rad)."""
    dp = np.linalg.norm(poses[:, :3] - poses[0, :3], axis=1)
    dq = 2 * np.arccos(np.clip(np.abs(poses[:, 3:] @ poses[0, 3:]), 0, 1))
    return bool(dp.max() < POS_TOL and dq.max() < ROT_TOL)


def fingers_closed(k, qpos: np.ndarray) -> bool:
    """Some frame has a finger joint of the platform's `finger_dims` nearer than its `finger_closed_below` to
    closed (Panda's fingers open to ±0.04 m)."""
    return bool((np.abs(qpos[:, list(k.finger_dims)]) < k.finger_closed_below).any())


def centre_gap(objects: np.ndarray, k: int, pixel: np.ndarray) -> float | None:
    """Native px from object `k`'s projected frame-0 centre `pixel` (scoring frame) to its nearest visible pixel in
    the label image `objects` (`Observation.objects`, native resolution); None when none of it is visible."""
    u, v = frame_xy(pixel, objects.shape[1], objects.shape[0])
    ys, xs = np.nonzero(objects == k + 1)
    return float(np.hypot(xs - u, ys - v).min()) if len(xs) else None


def centre_hidden(objects: np.ndarray | None, k: int, pixel: np.ndarray) -> dict | None:
    """Evidence that object `k` is not what the camera sees at its projected frame-0 centre: `centre_gap` beyond
    `CENTRE_SIGHT_MAX`, or nothing of it visible; None when it is seen there, or the platform gives no labels."""
    if objects is None:
        return None
    gap = centre_gap(objects, k, pixel)
    if gap is not None and gap <= CENTRE_SIGHT_MAX:
        return None
    return {"object_pixels": int((objects == k + 1).sum()), "centre_gap": gap}


class T4Builder(SourceSurvey, SuiteBuilder):
    suite = "t4"
    title = "T4 Interaction grounding"
    description = ("Validated no-contact rollouts, balanced over three kinds (`kind`): a distractor inserted where "
                   "the target lay in a same-task donor episode (LIBERO: a scene object the task does not use, "
                   "relocated; task still succeeds), false contact (expert arm "
                   "path, gripper clamped open), spatial proximity (target moved outside the robot's swept region). "
                   "The evaluated object never moves: `evaluated_object` (index `evaluated_object_index` in "
                   "`objects`), its frame-0 pixel `object_pixel_256` in the 256x256 scoring frame, and the "
                   "reference motion gate `gate_reference` (px; on a two-arm robot per hand, from each hand's "
                   "frame-0 pixel `hand_pixels_256`). Score: tracked object displacement <= 10 px behind a "
                   "distal-arm motion gate.")
    roles = ("reference",)

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        self.kind_tasks = self.kit.t4_kind_tasks(config.tasks)
        missing = [k for k, ts in self.kind_tasks.items() if not ts]
        if missing:
            raise ValueError(f"t4: no selected task serves kind(s) {', '.join(missing)}; "
                             f"needs {self.kit.t4_needs(missing)}")
        self.rig = RigCache(self.kit.t4_rig, self.kit.rigs_per_worker)

    def plan(self, slot: int) -> SlotPlan | None:
        kind = KINDS[slot % len(KINDS)]
        tasks = self.usable(self.kind_tasks[kind])
        return SlotPlan(tasks[(slot // len(KINDS)) % len(tasks)], kind) if tasks else None

    def close(self) -> None:
        self.rig.close()

    # -- validation -----------------------------------------------------------------------------
    def violation(self, rig: T4Rig, kind: str, p: Proposal, ro: Rollout) -> str | None:
        """The first failed check of a rollout: common validity (spec §5), then the kind's rule."""
        poses, contacts = ro.stack("object_poses"), ro.stack("contacts")
        if (why := rig.invalid(ro)):
            return why
        k = p.index
        if contacts[:, k].any():
            return "evaluated_object_contacted"
        if not static(poses[:, k].astype(np.float64)):
            return "evaluated_object_moved"
        if kind == "distractor":
            return None if ro.success else "task_failed"
        if contacts.any():
            return "other_object_contacted"
        if kind == "false_contact" and fingers_closed(self.kit, ro.stack("qpos")):
            return "gripper_closed"
        return None

    def hand_pixels(self, ref) -> np.ndarray | None:
        """Each hand's frame-0 pixel in the scoring frame (K, 2) on a robot with K > 1 arms (the gate is then
        per hand, `motion_gate`); None on a single arm."""
        tcp, arms = ref.observations[0].tcp_pose, len(self.kit.info.ee_names) // 7
        if arms < 2:
            return None
        size = frame_size(ref.observations[0].rgb)
        return np.array([project(tcp[7 * a:7 * a + 3], ref.intrinsic, ref.extrinsic, size) for a in range(arms)])

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        rig, kind = self.rig(plan.task), plan.group
        source = rig.expert.trajectory(seed)
        if source is None:
            return Dropped("source_failed")
        original = Proposal(source, rig.spec.objects, rig.spec.target, {}, {})
        base = rig.replay(rig.state, seed, original)  # the original rollout: swept region and object geometry
        simulated = len(source)
        proposal = getattr(rig, kind)(base, source, rig.sight(seed), rng)
        if isinstance(proposal, str):
            return Dropped(proposal, simulated_steps=simulated)
        ro = rig.replay(rig.state, seed, proposal)
        simulated += len(source)
        if (why := self.violation(rig, kind, proposal, ro)) is not None:
            return Dropped(why, simulated_steps=simulated)
        ref = rig.replay(rig.render, seed, proposal)  # only validated proposals are rendered
        rendered = len(source)
        if (why := self.violation(rig, kind, proposal, ref)) is not None:
            return Dropped(why, rendered, simulated)
        k = proposal.index
        pixel = project(ref.observations[0].object_poses[k, :3], ref.intrinsic, ref.extrinsic,
                        frame_size(ref.observations[0].rgb))
        if (hidden := centre_hidden(ref.observations[0].objects, k, pixel)) is not None:
            return Dropped("object_hidden_at_centre", rendered, simulated, hidden)
        stored, mask0 = stored_video(ref.stack("rgb"), self.kit.info.fps), ref.observations[0].mask
        rgb, hands = stored.frames, self.hand_pixels(ref)
        video = scoring_video(rgb)
        gate = motion_gate(video, mask0, hands=hands)
        if gate < GATE_MIN_REFERENCE:
            return Dropped("gate_too_small", rendered, simulated, {"gate": gate})
        motion = object_motion(video, pixel, mask0)
        if motion.textured_points < MIN_TEXTURED or motion.visible_fraction < MIN_VISIBLE:
            return Dropped("object_untrackable", rendered, simulated,
                           {"textured": motion.textured_points, "visible": motion.visible_fraction})
        score = t4_score(rgb, pixel, mask0, gate, hands=hands)
        if score.score != 100.0:
            return Dropped("reference_fails_tracker", rendered, simulated, {"d": score.displacement})
        if score.displacement > REFERENCE_D_MAX:
            return Dropped("reference_tracking_drifts", rendered, simulated, {"d": score.displacement})
        row = {
            "task": plan.task, "seed": seed, "instruction": rig.spec.instruction, "objects": list(proposal.objects),
            "source": "scripted_expert", "kind": kind, "evaluated_object": proposal.evaluated,
            "evaluated_object_index": k, "object_pixel_256": [float(x) for x in pixel], "gate_reference": gate,
            "displacement_reference": score.displacement, "object_visible_fraction": motion.visible_fraction,
            "interventions": {"reference": proposal.params},
        }
        if hands is not None:
            row["hand_pixels_256"] = hands.tolist()
        src = rig.replay(rig.render, seed, original)  # the unperturbed source rollout
        rendered += len(source)
        src_stored = stored_video(src.stack("rgb"), self.kit.info.fps)  # staged as is; decoded only if checked
        if kind == "false_contact" and (carried := passes_when_carried(src, src_stored.frames, k, pixel, mask0, gate,
                                                                       motion, hands)):
            return Dropped("tracker_misses_carrying", rendered, simulated, carried)
        return Kept(row, [RolloutArrays.from_rollout("reference", ref, stored),
                          RolloutArrays.from_rollout(SOURCE_ROLE, src, src_stored)], rendered, simulated)


def passes_when_carried(src, src_rgb: np.ndarray, k: int, pixel: np.ndarray, mask0: np.ndarray, gate: float, motion,
                        hands: np.ndarray | None) -> dict | None:
    """A false-contact reference's source rollout is the expert grasping the target and carrying it away, from the
    same first frame along the same arm path: exactly what a model that hallucinates contact would generate.
    Where the simulator moved the target more than MOTION_MAX px in the scoring frame, T4 must score that video 0;
    when it scores 100 instead (the tracker lost a small dark object under the fingers and kept following a still
    neighbour: LIBERO's chocolate pudding, docs/validity.md, T4 tracker), the instance cannot tell the two apart. Returns
    the evidence of such a miss, else None. `src_rgb`: the source's frames as stored."""
    size = frame_size(src.observations[0].rgb)
    truth = np.stack([project(o.object_poses[k, :3], src.intrinsic, src.extrinsic, size) for o in src.observations])
    moved = float(np.linalg.norm(truth - truth[0], axis=1).max())
    if moved <= MOTION_MAX:
        return None
    score = t4_score(src_rgb, pixel, mask0, gate, motion.visible_fraction, hands=hands)
    return None if score.score == 0 else {"true_d": moved, "d": score.displacement}
