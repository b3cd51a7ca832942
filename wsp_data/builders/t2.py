"""T2 Global trajectory coverage (spec §3.2): a receiver scene + the complete action stream of another task.

Proposal: the slot's receiver task and scene seed; a donor task drawn by the proposal RNG among the config's
other tasks that start in the receiver's arm configuration (`compatible_donors`); the donor stream is the
verified expert trajectory of the donor task at `donor_seed = seed + DONOR_SEED_OFFSET` (a seed of its own,
so the donor scene is not laid out by the receiver's random numbers).
Validation: the whole stream is executed from the receiver's reset state without rendering first
(`replay_problem`: the common checks of spec §5 plus two kinds of unintended collision), then rendered, and
kept only if RMFA can score it: at least one window with active robot pixels (`wsp_eval.flow`).
Stored per instance: donor task and seed, the receiver–donor motion mismatch (`motion_mismatch`) and the
number of scorable windows. Definitions and measurements: docs/suites/t2.md; on LIBERO (OSC delta streams: every
donor is compatible, arm motion = the commanded hand path, the LIBERO kit's `blocked`): docs/platforms/libero.md.
"""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import BuildConfig, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache
from wsp_data.builders.source_survey import SourceSurvey
from wsp_data.platforms import PlatformKit, joint_blocked, kit
from wsp_data.platforms.contract import Dropped, rollout_problem
from wsp_data.platforms.validity import MAX_JOINT_SPEED, check_rollout
from wsp_data.schema import FPS, MAX_ATTEMPTS, SEED_BASE, SEED_SPAN, SOURCE_ROLE
from wsp_data.staging import RolloutArrays
from wsp_eval.flow import active_pixels_per_window, reference_flows

TYPICAL_TRAJECTORIES = 8  # expert trajectories averaged into a task's typical arm stream
TYPICAL_MAX_SEEDS = 24  # training seeds tried to find them
MISMATCH_POINTS = 50  # time-normalised samples per stream
DONOR_SEED_OFFSET = SEED_SPAN // 2  # donor seeds live in the upper half of the T2 seed range
START_GAP = MAX_JOINT_SPEED / FPS  # rad: the largest first-step jump the instability check allows (0.5)
FLUNG_SPEED = 1.0  # m/s: horizontal speed of a task object that counts as flung


# -- motion mismatch -------------------------------------------------------------------------------------
def time_normalised(actions: np.ndarray, k: PlatformKit, points: int = MISMATCH_POINTS) -> np.ndarray:
    """The arm motion of a native stream (`k.arm_motion`: ManiSkill: the 7 joint targets, rad; LIBERO: the
    hand's commanded path, the cumulative OSC position deltas, m), linearly resampled at `points` evenly spaced
    instants of normalised time [0, 1] (first and last action kept): (points, k)."""
    arm = k.arm_motion(actions)
    if len(arm) < 2:
        raise ValueError("a stream needs at least two actions to be time-normalised")
    src, dst = np.linspace(0.0, 1.0, len(arm)), np.linspace(0.0, 1.0, points)
    return np.stack([np.interp(dst, src, arm[:, j]) for j in range(arm.shape[1])], axis=1)


def typical_arm_stream(source, k: PlatformKit, count: int = TYPICAL_TRAJECTORIES) -> np.ndarray:
    """Mean of the time-normalised arm motions of a task's first `count` verified expert trajectories on
    training seeds SEED_BASE["train"], +1, … (never test seeds): (MISMATCH_POINTS, k)."""
    streams = []
    for seed in range(SEED_BASE["train"], SEED_BASE["train"] + TYPICAL_MAX_SEEDS):
        if (a := source.trajectory(seed)) is not None:
            streams.append(time_normalised(a, k))
            if len(streams) == count:
                return np.mean(streams, axis=0)
    raise RuntimeError(f"{source.spec.name}: only {len(streams)} of the {count} expert trajectories needed for "
                       f"the typical arm stream succeeded on training seeds {SEED_BASE['train']}–"
                       f"{SEED_BASE['train'] + TYPICAL_MAX_SEEDS - 1}")


def motion_mismatch(donor_actions: np.ndarray, typical: np.ndarray, k: PlatformKit) -> float:
    """RMS over time-normalised samples and arm-motion dimensions of donor − receiver's typical (ManiSkill: rad
    over the 7 joints; LIBERO: m over the hand path's x, y, z)."""
    return float(np.sqrt(np.mean((time_normalised(donor_actions, k, len(typical)) - typical) ** 2)))


# -- validity ----------------------------------------------------------------------------------------------
def arm_blocked(qpos: np.ndarray, actions: np.ndarray) -> bool:
    """Joint-target streams: the arm is held back by something it collides with (table, a fixed fixture, a
    pinned object): some arm joint lags its target by more than BLOCK_RAD (0.15 rad) for BLOCK_STEPS (10)
    consecutive steps. `qpos` (T+1, 9). Other streams use their kit's `blocked` (LIBERO's OSC: `osc_blocked`)."""
    return joint_blocked(qpos, None, actions)


def object_flung(object_poses: np.ndarray) -> bool:
    """A task object is struck so hard that it moves faster than FLUNG_SPEED horizontally between frames.
    `object_poses` (T+1, K, 7), NaN-padded."""
    used = ~np.isnan(object_poses[0, :, 0])
    xy = object_poses[:, used, :2]
    return len(xy) > 1 and bool((np.linalg.norm(np.diff(xy, axis=0), axis=-1) * FPS > FLUNG_SPEED).any())


def replay_problem(qpos: np.ndarray, tcp_pose: np.ndarray, object_poses: np.ndarray, actions: np.ndarray,
                   qlimits: np.ndarray) -> str | None:
    """None for a valid donor replay of a joint-target stream (no action bounds), else the drop reason: a common
    check (`check_rollout`), `arm_blocked` or `object_flung` (unintended collisions)."""
    if (why := check_rollout(qpos, tcp_pose, object_poses, actions, qlimits)) is not None:
        return why
    if arm_blocked(qpos, actions):
        return "arm_blocked"
    if object_flung(object_poses):
        return "object_flung"
    return None


def collision_problem(k: PlatformKit, qpos, tcp_pose, object_poses, actions) -> str | None:
    """The two unintended collisions of a donor replay: the arm blocked, or a task object flung."""
    if k.blocked(qpos, tcp_pose, actions):
        return "arm_blocked"
    if object_flung(object_poses):
        return "object_flung"
    return None


# -- builder -----------------------------------------------------------------------------------------------
class _TaskRig:
    """One task in one worker: its expert source (donor streams, state-only replays), and what is made only when
    first asked for: its typical arm stream and a rendering env (when the task is a receiver). A task that is
    only a donor holds one state-only simulator."""

    def __init__(self, task: str, platform: str):
        self.task, self.platform, self.kit = task, platform, kit(platform)
        self.expert = self.kit.make_expert(task)
        self.spec = self.expert.spec
        self.state = self.expert.replayer
        self.qlimits = self.state.qlimits
        self._render = None

    def typical(self) -> np.ndarray:
        """The task's typical arm stream (`typical_arm_stream`: 8 expert runs); `T2Builder.typical` keeps it."""
        return typical_arm_stream(self.expert, self.kit)

    @property
    def rendering(self) -> bool:
        """Whether the rig holds a rendering simulator (it has been a receiver)."""
        return self._render is not None

    @property
    def render(self):
        if self._render is None:
            expert, self._render = self.kit.rig_simulators(self.task, self.expert)
            if expert is not self.expert:  # the platform closed it and runs a new one on the rendering simulator
                self.expert, self.state = expert, expert.replayer
        return self._render

    def close(self) -> None:
        self.expert.close()
        if self._render is not None:
            self._render.close()

    def invalid(self, ro) -> str | None:
        if (why := rollout_problem(self.kit, self.qlimits, ro)) is not None:
            return why
        return collision_problem(self.kit, ro.stack("qpos"), ro.stack("tcp_pose"), ro.stack("object_poses"),
                                 ro.actions)


class T2Builder(SourceSurvey, SuiteBuilder):
    suite = "t2"
    title = "T2 Global trajectory coverage"
    description = ("Cross-task replays: the complete expert action stream of a donor task, executed from the receiver "
                   "scene's initial state. Kept when the replay is executable and valid (joint limits, no instability, "
                   "the arm never blocked, no object flung) and has robot motion RMFA can score. Columns `donor_task`, "
                   "`donor_seed`, `mismatch` (RMS between the donor's time-normalised arm motion and the receiver "
                   "task's typical one: rad of joint targets on ManiSkill, m of commanded hand path on LIBERO; cut "
                   "into deciles at scoring) and `active_windows`. Score: RMFA.")
    roles = ("reference",)

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        if len(set(config.tasks)) < 2:
            raise ValueError("T2 needs at least two tasks: the donor task must differ from the receiver")
        if MAX_ATTEMPTS * config.count > DONOR_SEED_OFFSET:
            raise ValueError(f"T2 supports at most {DONOR_SEED_OFFSET // MAX_ATTEMPTS} instances per config: receiver "
                             f"scene seeds must stay below the donor seeds (offset {DONOR_SEED_OFFSET})")
        # an attempt holds two rigs (receiver and donor); every task's typical stream is kept apart from its rig,
        # so a platform's `rigs_per_worker` bounds T2 too (with at least those two)
        bound = self.kit.rigs_per_worker
        self.rig = RigCache(lambda task: _TaskRig(task, config.platform), None if bound is None else max(2, bound))
        self._typical: dict[str, np.ndarray] = {}

    def close(self) -> None:
        self.rig.close()

    def typical(self, task: str) -> np.ndarray:
        """`task`'s typical arm stream (`typical_arm_stream`), computed once per worker."""
        if task not in self._typical:
            self._typical[task] = self.rig(task).typical()
        return self._typical[task]

    def compatible_donors(self, receiver: str) -> list[str]:
        """The config's other tasks whose typical stream starts within START_GAP (every arm joint) of the
        receiver's: a donor from another start (e.g. the wrist turned by π/2) would jerk the arm in step one."""
        start = self.typical(receiver)[0]
        return [t for t in self.usable(tuple(dict.fromkeys(self.config.tasks)))
                if t != receiver and np.abs(self.typical(t)[0] - start).max() <= START_GAP]

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        donors = self.compatible_donors(plan.task)
        if self.kit.rigs_per_worker is not None:  # bounded: an earlier receiver's rendering env goes first (its
            #   task, if drawn as a donor, is made anew state-only), so a worker never holds two rendering envs
            self.rig.close_where(lambda key, rig: key != (plan.task,) and rig.rendering)
        receiver = self.rig(plan.task)  # after the typical streams: a bounded cache keeps it and the donor's rig
        if not donors:
            return Dropped("no_compatible_donor")
        donor_task = donors[int(rng.integers(len(donors)))]
        donor_seed = seed + DONOR_SEED_OFFSET
        stream = self.rig(donor_task).expert.trajectory(donor_seed)
        if stream is None:
            return Dropped("donor_source_failed", detail={"donor_task": donor_task})
        simulated = len(stream)
        if (why := receiver.invalid(receiver.state.replay(seed, stream))) is not None:
            return Dropped(why, simulated_steps=simulated, detail={"donor_task": donor_task})
        ro = receiver.render.replay(seed, stream)
        steps = len(stream)
        if (why := receiver.invalid(ro)) is not None:
            return Dropped(why, steps, simulated, {"donor_task": donor_task})
        active = active_pixels_per_window(*reference_flows(ro.stack("rgb"), ro.stack("mask"), FPS))
        if not (active > 0).any():
            return Dropped("no_scorable_motion", steps, simulated, {"donor_task": donor_task})
        own = receiver.expert.trajectory(seed)  # the unperturbed source: the receiver's own expert
        if own is None:
            return Dropped("source_failed", steps, simulated, {"donor_task": donor_task})
        src = receiver.render.replay(seed, own)
        steps += len(own)
        row = {
            "task": plan.task, "seed": seed, "instruction": receiver.spec.instruction,
            "objects": list(receiver.spec.objects), "source": f"scripted_expert (donor: {donor_task})",
            "donor_task": donor_task, "donor_seed": donor_seed,
            "mismatch": motion_mismatch(stream, self.typical(plan.task), self.kit),
            "active_windows": int((active > 0).sum()), "num_windows": len(active),
            "interventions": {"reference": {"donor_task": donor_task, "donor_seed": donor_seed}},
        }
        return Kept(row, [RolloutArrays.from_rollout("reference", ro), RolloutArrays.from_rollout(SOURCE_ROLE, src)],
                    steps, simulated)
