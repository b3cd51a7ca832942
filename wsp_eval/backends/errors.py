"""The one error every backend raises when it cannot run here (missing package, checkpoint or endpoint)."""


class BackendUnavailable(RuntimeError):
    """A backend cannot run: the message says what is missing and how to provide it."""
