"""The teleoperation page, end to end: the real server on a free port with a real ManiSkill env, driven by a
real headless Chromium through selenium (keys pressed on the page), the trajectory found on disk and replayed.

Needs the Debian packages `chromium` and `chromium-driver` and the pip package `selenium` (the project setup
installs them); skipped with a reason otherwise.
"""

from __future__ import annotations

import json
import shutil
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

CHROMEDRIVER = Path("/usr/bin/chromedriver")
TASK, SEED = "PickCube", 1


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if path := shutil.which(name):
            return path
    return None


def _browser():
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        pytest.skip("selenium is not installed (pip install selenium)")
    chromium = _chromium()
    if chromium is None or not CHROMEDRIVER.exists():
        pytest.skip("headless Chromium needs the Debian packages chromium and chromium-driver (/usr/bin/chromedriver)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1300,1000"):
        opts.add_argument(arg)
    return webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=opts)


@pytest.fixture(scope="module")
def driver():
    """A headless Chromium (module scope and listed first, so it is checked before the server starts and a
    missing browser skips at once)."""
    d = _browser()
    yield d
    d.quit()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from wsp_data.platforms.maniskill.teleop import TeleopServer

    srv = TeleopServer(TASK, SEED, tmp_path_factory.mktemp("teleop"), operator="H1", port=0)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()
    thread.join(10)


def _wait(cond, timeout: float = 30.0, what: str = "condition"):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = cond()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def _post(url: str, body: dict) -> tuple[int, dict]:
    req = urllib.request.Request(url, json.dumps(body).encode(), {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def test_browser_records_a_replay_verified_trajectory(driver, server):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    from wsp_data.platforms.maniskill.env import ManiSkillPlatform
    from wsp_data.platforms.maniskill.teleop import load_trajectory

    driver.get(server.url)
    _wait(lambda: driver.execute_script("return document.body.dataset.ready === '1'"), what="page init")
    # the live view and the expert animation are real, decoded images
    size = "return [arguments[0].complete, arguments[0].naturalWidth, arguments[0].naturalHeight]"
    live, expert = driver.find_element(By.ID, "live"), driver.find_element(By.ID, "expert")
    assert _wait(lambda: driver.execute_script(size, live)[1], what="live frame") == 512
    assert driver.execute_script(size, live) == [True, 512, 512]
    assert _wait(lambda: driver.execute_script(size, expert)[1], what="expert gif") == 128
    assert expert.is_displayed()
    # keys on the page: away, away, down, down, right, yaw, gripper toggle, hold → 8 control steps, then save
    keys = ["w", "w", "f", "f", "d", "q", Keys.SPACE, "h"]
    body = driver.find_element(By.TAG_NAME, "body")
    for k in keys:
        body.send_keys(k)
    _wait(lambda: driver.find_element(By.ID, "status").get_attribute("data-steps") == str(len(keys)),
          what="8 steps")
    assert "steps 8" in driver.find_element(By.ID, "status").text
    body.send_keys(Keys.ENTER)
    saved = _wait(lambda: driver.find_element(By.ID, "saved-path").text.strip(), what="saved path")
    assert driver.find_element(By.ID, "error").text == ""


    path = Path(saved)
    assert path.exists() and path.parent == server.out
    assert path.name.startswith(f"{TASK}_seed{SEED}_H1_") and path.suffix == ".npz"
    tr = load_trajectory(path)
    km = server.session.keymap
    assert tr.commands.tolist() == [km["w"], km["w"], "z-", "z-", km["d"], "yaw+", "toggle", "hold"]
    assert tr.actions.shape == (len(keys), 8) and tr.actions.dtype == np.float32  # one step per command
    assert (tr.task, tr.seed, tr.operator) == (TASK, SEED, "H1")
    prov = tr.provenance
    assert prov["kind"] == "human_teleop" and prov["tool"] == "wsp teleop" and prov["operator"] == "H1"
    assert prov["steps"] == len(keys) and prov["replay_verified"] is True and prov["success"] is False
    # the gripper column: open until the toggle, closed from it on
    assert tr.actions[:6, 7].tolist() == [1.0] * 6 and tr.actions[6:, 7].tolist() == [-1.0] * 2
    # the commanded TCP targets moved as asked: 1 cm per move command from the TCP at reset, yaw 0.1 rad
    def step(cmd: str) -> np.ndarray:
        v = np.zeros(3)
        v["xyz".index(cmd[0])] = 0.01 if cmd[1] == "+" else -0.01
        return v

    t, start = tr.ee_targets.astype(np.float64), tr.tcp_pose[0, :3]
    assert np.allclose(t[1, :3] - start, 2 * step(km["w"]), atol=1e-6)
    assert np.allclose(t[3, :3] - t[1, :3], 2 * step("z-"), atol=1e-6)
    assert np.allclose(t[4, :3] - t[3, :3], step(km["d"]), atol=1e-6)
    assert np.allclose(t[5:, :3], t[4, :3], atol=1e-6)
    assert abs(2 * np.arccos(min(1.0, abs(float(t[5, 3:] @ t[4, 3:])))) - 0.1) < 1e-4
    # replaying the stored stream under pd_joint_pos reproduces the recorded rollout
    with ManiSkillPlatform(TASK, render=False, objects=("cube",)) as p:
        ro = p.replay(SEED, tr.actions)
    assert np.allclose(ro.stack("tcp_pose"), tr.tcp_pose, atol=1e-6)
    assert np.allclose(ro.stack("qpos"), tr.qpos, atol=1e-6)
    assert np.allclose(ro.stack("object_poses")[:, 0], tr.object_poses[:, 0], atol=1e-6)
    assert ro.success == tr.success
    # the server's live state agrees with the file
    with urllib.request.urlopen(server.url + "state", timeout=30) as r:
        st = json.loads(r.read())
    assert st["steps"] == len(keys) and st["saved"] == [str(path)]
    assert np.allclose(st["tcp"], tr.tcp_pose[-1, :3], atol=1e-4)


def test_http_api_rejects_bad_requests(server):
    base = server.url
    code, err = _post(base + "command", {"cmd": "fly"})
    assert code == 400 and "unknown command" in err["error"]
    code, st = _post(base + "command", {"cmd": "reset"})
    assert code == 200 and st["steps"] == 0
    code, err = _post(base + "save", {})
    assert code == 400 and "nothing recorded" in err["error"]
    with urllib.request.urlopen(base + "frame.png", timeout=30) as r:
        assert r.headers["Content-Type"] == "image/png" and r.read()[:8] == b"\x89PNG\r\n\x1a\n"
    with urllib.request.urlopen(base + "expert.gif", timeout=30) as r:
        assert r.read()[:6] == b"GIF89a"
