"""The reference world model: network, training data, training loop, and the batched `wsp generate` model."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the model module imports torch: named here for the annotation only
    from wsp_models.reference.model import ReferenceModel


def reference_model() -> ReferenceModel:
    """The reference world model with its shipped checkpoints (`wsp generate --model reference`; needs torch, the
    `train` extra: ModuleNotFoundError without it)."""
    from wsp_models.reference.model import ReferenceModel

    return ReferenceModel()
