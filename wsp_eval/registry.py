"""One registry type for everything found by name: platforms, suite builders and scorers, backends, baselines.

A `Registry` maps names to objects of one kind. Built-in entries are registered in code; a registry with an
entry-point `group` also lists the entry points other installed distributions declare in that group, e.g.

    [project.entry-points."worldsimprobe.platforms"]
    myplatform = "my_package.kit:KIT"

Entry points are discovered on the first lookup or listing, and each is loaded when its name is first looked
up, so a broken plug-in only fails (with `PluginError` naming it) when it is used.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from importlib.metadata import EntryPoint, entry_points
from typing import Generic, TypeVar

T = TypeVar("T")


class PluginError(RuntimeError):
    """An entry point that cannot be used: it clashes with a registered name or fails to load."""


class Registry(Generic[T]):  # Generic, not PEP 695 syntax: the evaluation side stays importable on Python < 3.12
    """Objects of one `kind` (a word for messages: "platform", "flow backend") found by name."""

    def __init__(self, kind: str, group: str | None = None) -> None:
        self.kind = kind
        self.group = group
        self._entries: dict[str, T | EntryPoint] = {}
        self._discovered = group is None

    def register(self, name: str, obj: T | None = None) -> T | Callable[[T], T]:
        """Register `obj` as `name` and return it; without `obj`, a decorator that does so."""
        if obj is None:
            return lambda o: self.register(name, o)
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._entries[name] = obj
        return obj

    def __getitem__(self, name: str) -> T:
        self._discover()
        if name not in self._entries:
            raise KeyError(f"unknown {self.kind} {name!r}; known: {', '.join(self._entries)}")
        entry = self._entries[name]
        if isinstance(entry, EntryPoint):
            try:
                entry = self._entries[name] = entry.load()
            except Exception as e:
                raise PluginError(f"{self.kind} {name!r}: entry point {_describe(entry)} failed to load ({e})") from e
        return entry

    def __contains__(self, name: object) -> bool:
        self._discover()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        self._discover()
        return iter(list(self._entries))

    def __len__(self) -> int:
        self._discover()
        return len(self._entries)

    def _discover(self) -> None:
        """Add the entry points of `group` (once; built-in names may not be taken)."""
        if self._discovered:
            return
        found: dict[str, EntryPoint] = {}
        for ep in entry_points(group=self.group):
            if ep.name in self._entries or ep.name in found:
                raise PluginError(f"entry point {_describe(ep)}: a {self.kind} named {ep.name!r} is already registered")
            found[ep.name] = ep
        self._entries.update(found)
        self._discovered = True

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, group={self.group!r})"


def _describe(ep: EntryPoint) -> str:
    dist = f" of {ep.dist.name}" if ep.dist is not None else ""
    return f"{ep.name} = {ep.value} in group {ep.group}{dist}"
