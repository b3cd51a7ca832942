"""The one error every backend raises when it cannot run here (missing package, checkpoint or endpoint)."""

from __future__ import annotations

from pathlib import Path


class BackendUnavailable(RuntimeError):
    """A backend cannot run: the message says what is missing and how to provide it."""


def local_checkpoint(checkpoint: str | Path | None, backend: str, flag: str, example: str) -> Path:
    """The path of a heavy backend's checkpoint, which must already be on disk (nothing downloads).
    `backend` names it ("flow backend 'dpflow'"), `flag` is its CLI option, `example` a typical file."""
    if checkpoint is None:
        raise BackendUnavailable(f"{backend} needs a local checkpoint: {flag} PATH ({example}, downloaded beforehand)")
    path = Path(checkpoint)
    if not path.is_file():
        raise BackendUnavailable(f"{backend}: checkpoint {path} not found (nothing is downloaded at run time; fetch "
                                 "it once and pass its path)")
    return path
