"""World models written here (torch; the `train` extra). Importing this package needs no torch: it registers the
models by name in `wsp_eval.generate.MODELS` where the installed metadata does not declare their entry points
(`worldsimprobe.models`, pyproject.toml; an editable install's metadata is written when it is installed). The models
import torch when made."""

from __future__ import annotations

from wsp_eval.generate import MODELS
from wsp_models.reference import reference_model

if "reference" not in MODELS:
    MODELS.register("reference", reference_model)
