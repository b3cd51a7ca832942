"""Per-step simulator states and frames of one expert rollout per platform, to compare across machines and across
the CPU-specific code paths of the libraries underneath.

    # on each machine: dump, then compare the files side by side
    .venv/bin/python benchmarks/cross_cpu_states.py dump states_amd.npz
    .venv/bin/python benchmarks/cross_cpu_states.py compare states_amd.npz states_intel.npz
    # on one machine: the same rollouts with each library's CPU dispatch pinned, against the default
    .venv/bin/python benchmarks/cross_cpu_states.py pins --out DIR

`dump` scripts the expert of one task per platform (scene seed 0), replays it rendered and stores its actions,
joint positions, end-effector and object poses, RGB frames and robot masks. `compare` prints, per field, whether
the two files are identical and otherwise the first differing step and the largest difference. `pins` dumps once
with defaults and once per pin (in subprocesses, since the variables are read at library load), then compares:
numpy's dispatched SIMD without AVX-512, OpenBLAS's Haswell kernels, PyTorch's AVX2 kernels with MKL's AVX2 path,
and Mesa's software rasteriser restricted to AVX. Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROLLOUTS = (("libero", "libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket"),
            ("maniskill", "PickCube"), ("aloha", "transfer_cube"))
FIELDS = ("qpos", "tcp_pose", "object_poses", "rgb", "mask")
PINS = {
    "numpy SIMD without AVX-512": {"NPY_DISABLE_CPU_FEATURES":
                                   "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL"},
    "OpenBLAS Haswell kernels": {"OPENBLAS_CORETYPE": "Haswell"},
    "PyTorch AVX2, MKL AVX2": {"ATEN_CPU_CAPABILITY": "avx2", "MKL_CBWR": "AVX2"},
    "Mesa rasteriser AVX only": {"GALLIUM_OVERRIDE_CPU_CAPS": "avx"},
}


def dump(path: Path) -> None:
    from wsp_data.machine import cpu_model
    from wsp_data.platforms import kit

    arrays: dict[str, np.ndarray] = {}
    for platform, task in ROLLOUTS:
        k = kit(platform)
        source = k.make_expert(task)
        actions = source.trajectory(0)
        objects = tuple(source.spec.objects)
        source.close()
        if actions is None:
            print(f"{platform} {task}: the expert fails on scene 0; skipped")
            continue
        renderer = k.make_renderer(task, objects)
        rollout = renderer.replay(0, actions)
        renderer.close()
        arrays[f"{platform}/actions"] = actions
        for f in FIELDS:
            arrays[f"{platform}/{f}"] = rollout.stack(f)
    np.savez_compressed(path, cpu=np.array(cpu_model()), **arrays)
    print(f"{path}: {len(arrays)} arrays from {cpu_model()}")


def compare(a_path: Path, b_path: Path, quiet: bool = False) -> bool:
    """Print per field whether `a` and `b` agree (`quiet`: only the fields that differ); True when all agree."""
    a, b = np.load(a_path), np.load(b_path)
    print(f"{a_path.name} ({a['cpu']}) against {b_path.name} ({b['cpu']})")
    same = True
    for key in sorted(set(a.files) - {"cpu"}):
        if key not in b.files:
            print(f"  {key}: only in {a_path.name}")
            same = False
            continue
        x, y = a[key], b[key]
        if x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            if not quiet:
                print(f"  {key}: identical")
            continue
        same = False
        if x.shape != y.shape:
            print(f"  {key}: shapes {x.shape} and {y.shape}")
            continue
        d = np.nan_to_num(np.abs(x.astype(np.float64) - y.astype(np.float64))).reshape(len(x), -1).max(axis=1)
        first = int(np.nonzero(d > 0)[0][0])
        print(f"  {key}: first differs at step {first} of {len(x)} (by {d[first]:.3g}); largest difference "
              f"{d.max():.3g}")
    return same


def pins(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    here = Path(__file__).resolve()
    runs = {"default": {}, **PINS}
    files = {}
    for name, env in runs.items():
        files[name] = out / f"states_{len(files)}.npz"
        print(f"dumping: {name} {env or ''}", flush=True)
        subprocess.run([sys.executable, str(here), "dump", str(files[name])], env={**os.environ, **env},
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for name in PINS:
        print(f"\n{name}:")
        same = compare(files["default"], files[name], quiet=True)
        print(f"  {'every field identical' if same else 'differs (above)'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    sub.add_parser("dump").add_argument("out", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    sub.add_parser("pins").add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    if args.command == "dump":
        dump(args.out)
    elif args.command == "compare":
        compare(args.a, args.b)
    else:
        pins(args.out)


if __name__ == "__main__":
    main()
