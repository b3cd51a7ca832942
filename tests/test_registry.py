"""`wsp_eval.registry.Registry`: one type for platforms, suites, backends and baselines, open to other
distributions through entry points (found here from a real `*.dist-info` on the path, not a mock)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from wsp_data.builders import BUILDERS
from wsp_data.platforms import KITS
from wsp_eval.backends import FLOW, JUDGE, TRACKER
from wsp_eval.baselines import BASELINES
from wsp_eval.registry import PluginError, Registry
from wsp_eval.suites import SCORERS

GROUP = "worldsimprobe.test_things"


def install_plugin(site: Path, entry_points: str, module: str = "") -> None:
    """A distribution `wsp-test-plugin` in `site`: its metadata, entry points and (optionally) a module."""
    info = site / "wsp_test_plugin-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: wsp-test-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))
    if module:
        (site / "wsp_test_plugin.py").write_text(textwrap.dedent(module))


def test_every_named_thing_is_one_registry_type():
    for registry in (KITS, BUILDERS, SCORERS, BASELINES, FLOW, TRACKER, JUDGE):
        assert isinstance(registry, Registry)
    assert list(KITS)[:2] == ["maniskill", "libero"] and set(SCORERS) == {"t1", "t2", "t3", "t4", "t5"}
    assert set(BUILDERS) == {*SCORERS, "train"} and list(BASELINES)[0] == "oracle"


def test_register_look_up_and_list():
    things: Registry[int] = Registry("thing")
    assert things.register("one", 1) == 1

    @things.register("double")
    def double(x: int) -> int:
        return 2 * x

    assert things["one"] == 1 and things["double"] is double
    assert list(things) == ["one", "double"] and len(things) == 2 and "one" in things and "two" not in things


def test_unknown_name_names_the_kind_and_the_known_names():
    things: Registry[int] = Registry("thing")
    things.register("one", 1)
    with pytest.raises(KeyError, match=r"unknown thing 'two'; known: one"):
        things["two"]
    with pytest.raises(KeyError, match=r"unknown platform 'mars'; known: maniskill, libero"):
        KITS["mars"]


def test_duplicate_registration_is_refused():
    things: Registry[int] = Registry("thing")
    things.register("one", 1)
    with pytest.raises(ValueError, match=r"thing 'one' is already registered"):
        things.register("one", 2)
    assert things["one"] == 1


def test_entry_points_are_found_and_loaded_on_lookup(tmp_path, monkeypatch):
    install_plugin(tmp_path, f"""
        [{GROUP}]
        extra = wsp_test_plugin:THING
        broken = wsp_test_plugin_missing:THING
    """, module="THING = {'answer': 42}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "wsp_test_plugin", raising=False)
    things: Registry[dict] = Registry("thing", GROUP)
    things.register("builtin", {})
    assert "wsp_test_plugin" not in sys.modules  # nothing is discovered before it is asked for
    assert list(things) == ["builtin", "extra", "broken"]
    assert "wsp_test_plugin" not in sys.modules  # listing does not load
    assert things["extra"] == {"answer": 42}
    assert things["extra"] is sys.modules["wsp_test_plugin"].THING
    with pytest.raises(PluginError, match=r"thing 'broken': entry point broken = wsp_test_plugin_missing:THING in "
                                          rf"group {GROUP} of wsp-test-plugin failed to load"):
        things["broken"]


def test_an_entry_point_may_not_take_a_registered_name(tmp_path, monkeypatch):
    install_plugin(tmp_path, f"[{GROUP}]\nbuiltin = wsp_test_plugin:THING\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    things: Registry[int] = Registry("thing", GROUP)
    things.register("builtin", 1)
    with pytest.raises(PluginError, match=r"entry point builtin = wsp_test_plugin:THING .*already registered"):
        things["builtin"]


def test_a_third_party_platform_is_a_kit(tmp_path):
    """End to end, in a fresh interpreter: a distribution's `worldsimprobe.platforms` entry point is a platform
    `kit()` returns and `wsp build --platform` accepts."""
    install_plugin(tmp_path, "[worldsimprobe.platforms]\ntoy = wsp_test_plugin:KIT\n", module="""
        from wsp_data.platforms import kit
        class Toy(type(kit("maniskill"))):
            name = "toy"
        KIT = Toy()
    """)
    script = ("from wsp_data.platforms import KITS, kit; from wsp_data.builders import BuildConfig; "
              "from wsp_eval.cli import parser; "
              "BuildConfig('t1', 'toy', 1, ('PickCube',)); "
              "argv = ['build', '--suite', 't1', '--platform', 'toy']; assert parser(argv).parse_args(argv).platform == 'toy'; "
              "print(list(KITS), kit('toy').name)")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["['maniskill',", "'libero',", "'aloha',", "'toy']", "toy"]
