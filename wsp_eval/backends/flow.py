"""Optical-flow backends for RMFA (spec §4.6): OpenCV DIS (default, CPU, no weights) and DPFlow through
ptlflow with a local checkpoint (optional). A backend maps RGB samples on the 160×120 grid to the flows
between consecutive samples, in pixels of that grid: `flows(samples, needed=None)`, where `needed` (one bool per
pair) names the pairs RMFA will read (the others may be left zero)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from wsp_eval.backends.errors import BackendUnavailable, local_checkpoint


class DISFlow:
    """OpenCV DIS optical flow, preset MEDIUM, one thread per worker (the default backend)."""

    name = "dis"

    def __init__(self):
        self.version = f"opencv {cv2.__version__} DIS preset MEDIUM"

    def flows(self, samples: np.ndarray, needed: np.ndarray | None = None) -> np.ndarray:
        """(K+1, H, W, 3) uint8 RGB → (K, H, W, 2) float32 flows from sample k to k + 1; with `needed` (K,) bool,
        only those (the rest zero). Each pair is computed alone (DIS keeps no state between calls), so a flow
        is the same whether or not its neighbours are."""
        cv2.setNumThreads(1)
        dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        out = np.zeros((max(len(samples) - 1, 0), *samples.shape[1:3], 2), np.float32)
        pairs = range(len(out)) if needed is None else np.flatnonzero(needed)
        grey: dict[int, np.ndarray] = {}
        for k in pairs:
            for j in (k, k + 1):
                if j not in grey:
                    grey[j] = cv2.cvtColor(samples[j], cv2.COLOR_RGB2GRAY)
            out[k] = dis.calc(grey[k], grey[k + 1], None)
        return out


class DPFlow:
    """DPFlow (the paper's flow model, `things` weights) through ptlflow, from a local checkpoint file.

    Needs `pip install ptlflow` and a checkpoint already on disk; nothing is downloaded. Runs on CUDA when
    available, else on the CPU (slow)."""

    name = "dpflow"

    def __init__(self, checkpoint: str | Path | None = None, device: str | None = None):
        path = local_checkpoint(checkpoint, "flow backend 'dpflow'", "--flow-checkpoint",
                                "e.g. dpflow-things.ckpt from ptlflow's model zoo")
        try:
            import ptlflow
            import torch
            from ptlflow.utils.io_adapter import IOAdapter
        except ImportError as e:
            raise BackendUnavailable(f"flow backend 'dpflow' needs ptlflow ({e}); install it with "
                                     "`pip install ptlflow` or use the default backend 'dis'") from None
        self._torch, self._adapter_cls = torch, IOAdapter
        self._device = device or ("cuda" if torch.cuda.is_available() else "cpu")
        self._model = ptlflow.get_model("dpflow", ckpt_path=str(path)).eval().to(self._device)
        self.version = f"ptlflow {getattr(ptlflow, '__version__', '?')} dpflow {path.name}"

    def flows(self, samples: np.ndarray, needed: np.ndarray | None = None) -> np.ndarray:
        out = np.zeros((max(len(samples) - 1, 0), *samples.shape[1:3], 2), np.float32)
        if not len(out):
            return out
        adapter = self._adapter_cls(self._model, samples.shape[1:3])
        with self._torch.no_grad():
            for k in range(len(out)) if needed is None else np.flatnonzero(needed):
                inputs = adapter.prepare_inputs([samples[k], samples[k + 1]])
                inputs = {key: v.to(self._device) for key, v in inputs.items()}
                preds = adapter.unscale(self._model(inputs))
                out[k] = preds["flows"][0, 0].permute(1, 2, 0).cpu().numpy()
        return out
