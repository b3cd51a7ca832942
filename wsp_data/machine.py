"""The CPU a build runs on and the memory its workers hold, recorded with every decided slot.

A slot's decision is byte-identical on one CPU type, and may differ in its last bits on another (docs/performance.md,
"Across machines"): the release says which slots each CPU type decided, and a build whose slots come from more
than one warns.
"""

from __future__ import annotations

import ctypes
import functools
import platform
import resource
from pathlib import Path


@functools.cache
def cpu_model() -> str:
    """This machine's CPU: `/proc/cpuinfo`'s model name, the architecture with the x86 family and model (a virtual
    machine's model name is often generic: "AMD EPYC" names several generations) and the widest x86 vector
    extension, e.g. `AMD EPYC (x86_64 family 25 model 17, AVX-512)`."""
    name, flags, ids = "", set(), {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            key = key.strip()
            if key == "model name" and not name:
                name = value.strip()
            elif key == "flags" and not flags:
                flags = set(value.split())
            elif key in ("cpu family", "model") and key not in ids:
                ids[key] = value.strip()
    except OSError:
        pass
    vector = next((label for flag, label in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"))
                   if flag in flags), "")
    arch = platform.machine() or "unknown architecture"
    if "cpu family" in ids and "model" in ids:
        arch += f" family {ids['cpu family']} model {ids['model']}"
    details = ", ".join(x for x in (arch, vector) if x)
    return f"{name or platform.processor() or 'unknown CPU'} ({details})"


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, MB (Linux reports kB, macOS bytes)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return round(peak / (1024 * 1024 if platform.system() == "Darwin" else 1024), 1)


def return_freed_memory() -> None:
    """Hand the heap's freed pages back to the system (glibc's `malloc_trim`; nothing elsewhere): a closed simulator
    otherwise leaves a few hundred MB of free heap counted in the worker's resident memory."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def mixed_cpus_warning(config: str, cpus: dict[str, list[int]]) -> str | None:
    """One line when the slots of `config` were decided on more than one CPU type (`cpus`: type → slots)."""
    if len(cpus) < 2:
        return None
    parts = "; ".join(f"{cpu}: {len(slots)} slot(s)" for cpu, slots in sorted(cpus.items()))
    return (f"[wsp build] warning: {config}'s slots were decided on {len(cpus)} CPU types ({parts}); a slot is "
            "byte-identical only to one decided on the same CPU type, so this release matches no single-machine "
            "build (build_report.json lists the slots per CPU type)")
