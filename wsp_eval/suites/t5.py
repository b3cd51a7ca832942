"""T5 Interaction dynamics (spec §3.5): object-response fidelity (`wsp_eval.object_track`, spec §4.3) of the
generated clip against the reference's evaluated object, gated by the arm: S = F · min(1, RMFA_arm / ARM_FULL),
where F is the fidelity and RMFA_arm is RMFA (spec §4.2) of the same clip on the robot's reference masks. Averaged
within primitive, then across primitives.

Beside the score, the paper's protocol as a reported column, "primitive recognised": the label judge (spec §4.5)
sees 12 uniformly sampled frames (plus the stored frame-0 object position) and returns a primitive label and two
booleans; 100·1[label = intended]·1[agent ok]·1[object ok]. It also runs once on each simulator reference, for its
reported agreement."""

from __future__ import annotations

from wsp_eval.backends.judge import sample_frames, score_verdict
from wsp_eval.flow import clip_duration, mean_window_score, score_windows, video_flows, windowed_reference
from wsp_eval.object_track import fidelity, object_track, positions, relative_error
from wsp_eval.video import nearest_indices, timestamps

SUITE, TITLE = "t5", "Interaction dynamics"
ROLES = ("reference",)
NEEDS = ("flow", "judge")
GROUP_BY, BALANCED = "primitive", True
REFERENCE_RESULTS = True  # `prepare` keeps the judge's result on the reference in the reference-result cache
ARM_FULL = 50.0  # RMFA of the arm at and above which the arm gate is open (1); below it the score scales down


def _judge(frames, row: dict, platform: str, judge) -> tuple[float, dict]:
    verdict = judge.judge(sample_frames(frames), tuple(float(x) for x in row["object_pixel_256"]), platform)
    detail = {"label": verdict.label, "agent_ok": verdict.agent_ok, "object_ok": verdict.object_ok}
    return score_verdict(verdict, row["primitive"]), detail


class _Reference:
    """The reference side of one instance: the evaluated object's templates (whole clip) and the arm's RMFA windows
    over a common duration (the whole clip unless a generated video is shorter), computed once per duration."""

    def __init__(self, ref, backends):
        self.ref, self.row, self.platform = ref, ref.row, ref.platform
        self.duration = clip_duration(ref.num_frames("reference"), ref.fps)
        self.flow = backends.flow
        k = int(self.row["evaluated_index"])
        self.track = object_track(ref.frames("reference"), ref.object_masks("reference"), k + 1,
                                  ref.masks("reference"), ref.object_pose("reference", k))
        self._arm: dict[float, object] = {}
        self.judged = ref.cached(self._judge_reference(backends.judge), ("score",))

    def _judge_reference(self, judge):
        def verdict() -> dict:
            score, detail = _judge(self.ref.frames("reference"), self.row, self.platform, judge)
            return {"score": score, **detail}
        return verdict

    def arm(self, duration: float):
        key = round(min(duration, self.duration), 9)
        if key not in self._arm:
            flows = self.ref.reference_flows("reference", key, self.flow)
            self._arm[key] = windowed_reference(flows.flows, flows.masks)
        return self._arm[key]


def prepare(ref, backends) -> _Reference:
    return _Reference(ref, backends)


def score_seed(prepared: _Reference, videos, backends) -> tuple[float, dict]:
    frames, fps = videos["reference"]
    duration = min(prepared.duration, clip_duration(len(frames), fps))
    ref_times = timestamps(prepared.ref.num_frames("reference"), prepared.ref.fps)
    shown = nearest_indices(timestamps(len(frames), fps), ref_times[ref_times <= duration + 1e-9])
    found = positions(frames, prepared.track, shown)
    x = relative_error(found)
    object_fidelity = fidelity(x)
    arm_ref = prepared.arm(duration)
    arm = mean_window_score(score_windows(video_flows(frames, fps, duration, backends.flow, arm_ref.needed),
                                          arm_ref)) or 0.0
    recognised, verdict = _judge(frames, prepared.row, prepared.platform, backends.judge)
    score = object_fidelity * min(1.0, arm / ARM_FULL)
    return score, {"object_fidelity": round(object_fidelity, 3), "object_error": round(x, 4), "object_blur": found.blur,
                   "object_arm_blur": found.arm, "object_vacated": round(found.vacated, 4),
                   "object_turned": round(found.turned, 4), "object_windowed": round(found.windowed, 4),
                   "object_stepped": round(found.stepped, 4),
                   "arm_rmfa": round(arm, 3), "recognised": recognised, **verdict}


def groups(rows: list[dict]) -> list[str]:
    return [r["primitive"] for r in rows]


def reference_check(prepared: _Reference) -> dict:
    """The judge's verdict on the simulator reference (for its reported agreement)."""
    return prepared.judged
