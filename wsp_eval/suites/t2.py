"""T2 Global trajectory coverage (spec §3.2): RMFA (`wsp_eval.flow`) of the generated video against the
cross-task reference, over their common duration; report cut by receiver–donor mismatch decile (rank by
`mismatch`, ties by `instance_id`; decile 1 = smallest mismatch)."""

from __future__ import annotations

import numpy as np

from wsp_eval.flow import (
    clip_duration, mean_window_score, score_windows, video_flows, windowed_reference,
)

SUITE, TITLE = "t2", "Global trajectory coverage"
ROLES = ("reference",)
NEEDS = ("flow",)
GROUP_BY, BALANCED = "mismatch decile", False
REFERENCE_RESULTS = False
DECILES = 10


class _Reference:
    """Reference flows per common duration (the full clip unless a generated video is shorter); the reference
    video and masks are decoded only when the flow cache does not hold them."""

    def __init__(self, ref, role: str, backend):
        self.ref, self.role, self.backend = ref, role, backend
        self.duration = clip_duration(ref.num_frames(role), ref.fps)
        self._flows: dict[float, object] = {}

    def flows(self, duration: float):
        """The reference's windows over `duration` (`windowed_reference`), with which of its flows have a non-empty
        active set (`needed`): the only flows of a generated video RMFA reads."""
        key = round(min(duration, self.duration), 9)
        if key not in self._flows:
            ref = self.ref.reference_flows(self.role, key, self.backend)
            self._flows[key] = windowed_reference(ref.flows, ref.masks)
        return self._flows[key]


def prepare(ref, backends, role: str = "reference") -> _Reference:
    return _Reference(ref, role, backends.flow)


def rmfa(prepared: _Reference, frames: np.ndarray, fps: float, backend) -> tuple[float, dict]:
    """RMFA of one generated video; a video too short for one flow (or with no scorable window) scores 0."""
    duration = min(prepared.duration, clip_duration(len(frames), fps))
    ref = prepared.flows(duration)
    per_window = score_windows(video_flows(frames, fps, duration, backend, ref.needed), ref)
    score = mean_window_score(per_window)
    return (0.0 if score is None else score), {
        "common_seconds": duration, "flows": len(ref.needed),
        "windows": [None if s is None else round(s, 2) for s in per_window]}


def score_seed(prepared: _Reference, videos, backends) -> tuple[float, dict]:
    frames, fps = videos["reference"]
    return rmfa(prepared, frames, fps, backends.flow)


def groups(rows: list[dict]) -> list[str]:
    order = sorted(range(len(rows)), key=lambda i: (rows[i]["mismatch"], rows[i]["instance_id"]))
    out = [""] * len(rows)
    for rank, i in enumerate(order):
        out[i] = str(rank * DECILES // len(rows) + 1)
    return out
