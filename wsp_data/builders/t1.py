"""T1 Local action calibration (spec §3.1).

Proposal: a verified expert source trajectory; one non-gripper action dimension, one direction, one
window of `WINDOW` steps, two distinct magnitudes from `MAGNITUDES` in native units (ManiSkill: rad of a
joint target; LIBERO: OSC units, ×0.05 m or ×0.5 rad per step), the smaller one "small". The triplet shares the scene seed, dimension, direction and window.
Validation: both variants replayed unrendered first (task success + common validity, spec §5); only then
all three are rendered, and the triplet is kept when all three rendered references succeed and
0 < D(x⁰, xˢ) < D(x⁰, xˡ), D being the temporally aligned full-video MSE on the simulator's own frames.
Stored per instance: D⁰ˢ, D⁰ˡ, r* = D⁰ˢ / D⁰ˡ and every perturbation parameter.
"""

from __future__ import annotations

import numpy as np

from wsp_data.builders.base import BuildConfig, Kept, SlotPlan, SuiteBuilder
from wsp_data.builders.rig import RigCache
from wsp_data.builders.source_survey import SourceSurvey
from wsp_data.platforms.contract import Dropped, TaskRig
from wsp_data.schema import FPS
from wsp_data.staging import RolloutArrays
from wsp_eval.video import aligned_mse

MAGNITUDES = (0.0025, 0.005, 0.010, 0.015, 0.020)
WINDOW = 20  # steps (1 s at 20 Hz)


class T1Builder(SourceSurvey, SuiteBuilder):
    suite = "t1"
    title = "T1 Local action calibration"
    description = ("Triplets (original, small, large): one non-gripper dimension of the native action perturbed in one "
                   "direction over one 1 s window at two magnitudes from {0.0025, 0.005, 0.010, 0.015, 0.020} "
                   "(native units: rad on ManiSkill, OSC units on LIBERO). All three "
                   "references succeed and 0 < D0s < D0l on the simulator's own frames; columns `d_os`, `d_ol` "
                   "and `r_star` hold the reference-side MSEs and ratio. Score: response-ratio calibration.")
    roles = ("original", "small", "large")

    def __init__(self, config: BuildConfig):
        super().__init__(config)
        self.rig = RigCache(lambda task: TaskRig(task, config.platform), self.kit.rigs_per_worker)

    def close(self) -> None:
        self.rig.close()

    @staticmethod
    def perturb(actions: np.ndarray, dim: int, direction: int, start: int, magnitude: float) -> np.ndarray:
        out = actions.copy()
        out[start:start + WINDOW, dim] += direction * magnitude
        return out

    def attempt(self, plan: SlotPlan, seed: int, rng: np.random.Generator) -> Kept | Dropped:
        task = plan.task
        rig = self.rig(task)
        source = rig.expert.trajectory(seed)
        if source is None:
            return Dropped("source_failed")
        if len(source) < WINDOW + 2:
            return Dropped("source_too_short")
        dims = rig.kit.t1_dims()
        dim = dims[int(rng.integers(len(dims)))]
        direction = int(rng.choice([-1, 1]))
        start = int(rng.integers(0, len(source) - WINDOW + 1))
        small, large = sorted(float(m) for m in rng.choice(MAGNITUDES, size=2, replace=False))
        streams = {"original": source, "small": self.perturb(source, dim, direction, start, small),
                   "large": self.perturb(source, dim, direction, start, large)}
        simulated = 0
        for role in ("small", "large"):  # unrendered validation first: rejected proposals cost no rendering
            ro = rig.state.replay(seed, streams[role])
            simulated += len(streams[role])
            if (why := rig.invalid(ro)) is not None:
                return Dropped(why, simulated_steps=simulated)
            if not ro.success:
                return Dropped("variant_failed", simulated_steps=simulated)
        rendered = {role: rig.render.replay(seed, s) for role, s in streams.items()}
        steps = sum(len(s) for s in streams.values())
        for role, ro in rendered.items():
            if not ro.success:
                return Dropped("rendered_reference_failed", steps, simulated, {"role": role})
            if (why := rig.invalid(ro)) is not None:
                return Dropped(why, steps, simulated)
        rgb = {role: ro.stack("rgb") for role, ro in rendered.items()}
        d_os = aligned_mse(rgb["original"], rgb["small"], FPS, FPS)
        d_ol = aligned_mse(rgb["original"], rgb["large"], FPS, FPS)
        if d_os <= 0:
            return Dropped("zero_response", steps, simulated)
        if not d_os < d_ol:
            return Dropped("not_monotone", steps, simulated)
        window = {"dim": dim, "direction": direction, "start": start, "end": start + WINDOW}
        row = {
            "task": task, "seed": seed, "instruction": rig.spec.instruction, "objects": list(rig.spec.objects),
            "source": "scripted_expert", "perturb_dim": dim, "perturb_direction": direction,
            "window_start": start, "window_end": start + WINDOW, "magnitude_small": small, "magnitude_large": large,
            "d_os": d_os, "d_ol": d_ol, "r_star": d_os / d_ol,
            "interventions": {"original": {}, "small": {**window, "magnitude": small},
                              "large": {**window, "magnitude": large}},
        }
        return Kept(row, [RolloutArrays.from_rollout(role, rendered[role]) for role in self.roles], steps, simulated)
