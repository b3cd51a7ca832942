"""Point-tracker backends for T4 (spec §4.6): colour region + pyramidal Lucas–Kanade with a forward–backward
check (default, CPU, no weights; `wsp_eval.tracking`) and TAPNext through DeepMind's `tapnet` package with a
local checkpoint (optional). A backend prepares a video for tracking (`prepare`), tracks query points from
frame 0 (`track`) and the evaluated object's query grid (`track_object`), returning `wsp_eval.tracking.Tracks`
in the 256×256 scoring frame."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from wsp_eval import tracking
from wsp_eval.backends.errors import BackendUnavailable, local_checkpoint


class LKTracker:
    """The evaluated object by its colour region where its colour is distinct, else OpenCV pyramidal
    Lucas–Kanade with forward–backward check; the arm by LK (the default backend, `wsp_eval.tracking`)."""

    name = "lk"

    def __init__(self):
        self.version = (f"opencv {cv2.__version__} colour region (ΔE {tracking.COLOUR_DELTA_E:g}, occlusion fit) "
                        f"+ pyramidal LK with forward-backward check (object grid r = {tracking.LK_QUERY_RADIUS:g} px)")

    @staticmethod
    def prepare(frames: np.ndarray) -> tracking.ScoringVideo:
        return tracking.scoring_video(frames)

    @staticmethod
    def track(video: tracking.ScoringVideo, points: np.ndarray, *, anchored: bool) -> tracking.Tracks:
        return tracking.track(video.grey, points, anchored=anchored)

    @staticmethod
    def track_object(video: tracking.ScoringVideo, object_px: np.ndarray, robot_mask0: np.ndarray | None
                     ) -> tracking.Tracks:
        return tracking.object_tracks(video, object_px, robot_mask0)


class TAPNextTracker:
    """TAPNext / TAPNext++ (the paper's tracker) from a local checkpoint through `tapnet`'s PyTorch port.

    Needs `pip install tapnet` (with torch) and a checkpoint on disk; nothing is downloaded. Points are
    visible where the model's visibility exceeds 0.5 (spec §4.4); the anchored/chained distinction of the
    LK backend does not apply (the model tracks every point from frame 0 itself)."""

    name = "tapnext"
    VISIBLE = 0.5

    def __init__(self, checkpoint: str | Path | None = None, device: str | None = None):
        path = local_checkpoint(checkpoint, "tracker backend 'tapnext'", "--tracker-checkpoint",
                                "e.g. bootstapnext_ckpt.npz from the tapnet repository")
        try:
            import torch
            from tapnet.tapnext.tapnext_torch import TAPNext
            from tapnet.tapnext.tapnext_torch_utils import restore_model_from_jax_checkpoint
        except ImportError as e:
            raise BackendUnavailable(f"tracker backend 'tapnext' needs the tapnet package ({e}); install it or use "
                                     "the default backend 'lk'") from None
        self._torch = torch
        self._device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        model = TAPNext(image_size=(tracking.SCORING_SIZE, tracking.SCORING_SIZE))
        self._model = restore_model_from_jax_checkpoint(model, str(path)).eval().to(self._device)
        self.version = f"tapnet TAPNext {path.name}"

    @staticmethod
    def prepare(frames: np.ndarray) -> np.ndarray:
        size = (tracking.SCORING_SIZE, tracking.SCORING_SIZE)
        return np.stack([cv2.resize(f, size, interpolation=cv2.INTER_LINEAR) for f in np.asarray(frames)])

    def track_object(self, video: np.ndarray, object_px: np.ndarray, robot_mask0: np.ndarray | None
                     ) -> tracking.Tracks:
        return self.track(video, tracking.query_grid(object_px), anchored=True)

    def track(self, video: np.ndarray, points: np.ndarray, *, anchored: bool) -> tracking.Tracks:
        torch = self._torch
        points = np.asarray(points, np.float32).reshape(-1, 2)
        if len(points) == 0:
            return tracking.Tracks(np.zeros((len(video), 0, 2), np.float32), np.zeros((len(video), 0), bool))
        frames = torch.from_numpy(video).float().div(127.5).sub(1.0)[None].to(self._device)
        queries = torch.from_numpy(np.c_[np.zeros(len(points)), points[:, ::-1]]).float()[None].to(self._device)
        with torch.no_grad():
            tracks, logits, *_ = self._model(video=frames, query_points=queries)
        pos = tracks[0].cpu().numpy()[..., ::-1].astype(np.float32)  # (T, N, 2) as (x, y)
        vis = torch.sigmoid(logits[0]).cpu().numpy().reshape(len(video), -1) > self.VISIBLE
        return tracking.Tracks(pos, vis)
