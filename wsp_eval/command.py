"""What a `wsp` sub-command is (`Command`), the error it raises for the user to fix (`CliError`) and the argument
types commands share. A module of its own, so that `wsp_eval.cli` run as `python -m` (then `__main__`) and the
commands other modules define (`wsp_data.commands`) share one `CliError` class.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass


class CliError(Exception):
    """A command that cannot go on; `main` prints the message on one line and exits 2."""


@dataclass(frozen=True)
class Command:
    """A `wsp` sub-command from another module: its one-line help, what adds its arguments to its parser, and
    what runs it (returning the exit code; CliError for an error the user can fix)."""

    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


def positive(text: str) -> int:
    """An argparse type: a whole number above 0."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {v}")
    return v
