"""Human teleoperation: a local web page that drives the real simulator and records T3 source trajectories.

    wsp teleop --task PickCube --seed 3 --operator H1 [--port 8765] [--out teleop]

serves a page on http://127.0.0.1:PORT/ showing the live camera view of the episode beside the expert
rollout for the same task and seed. Buttons and keys move the end effector (±x, ±y, ±z in 1 cm steps, yaw
in 0.1 rad steps) and open/close the gripper; every command is **one 20 Hz control step** of the simulator,
so a saved trajectory has exactly as many steps as stepping commands were sent since the last reset.

**How a command becomes an action (the recording).** The session is a `SkillScript` (the experts' scripting
tool, `skills.py`) on a *rendering* `pd_ee_pose` env: a command moves the last commanded TCP target by the
step (translation in world axes; yaw about the vertical through the TCP), the controller's IK solves it, the
env steps once, and the arm controller's joint targets plus the gripper command are appended to an 8-D
`pd_joint_pos` stream, exactly as the scripted experts record. The target is kept on a 3 cm leash around
the actual TCP (pressing into the table or an object never winds it up), and a target the IK cannot reach is
dropped again (the arm holds; the state says `ik_failed`).

**Live view.** The same `pd_ee_pose` env renders the 128×128 `base_camera` on every step (one render per
command). This is cheaper than a second rendering `pd_joint_pos` env stepped in lockstep (that would double
the physics and add a second renderer) and shows the same thing, since the replay is step-for-step the same
rollout (checked at every save).

**Saving.** `save` replays the recorded stream under `pd_joint_pos` in a fresh state-only env from the same
seed and compares, at every step, joint positions, the TCP pose and the task objects' poses with the live
rollout, and the final success. The result is written as `<out>/<task>_seed<seed>_<operator>_<timestamp>.npz`
(`load_trajectory` reads it back) with provenance `{"kind": "human_teleop", "operator", "tool": "wsp teleop",
"steps", "success", "replay_verified", …}`. A failed or unsuccessful attempt is saved too (T3 keeps both).

**Server.** `http.server.ThreadingHTTPServer` on 127.0.0.1 only; one session per server. Every simulator
call runs on one dedicated thread (a single-worker executor, the lock around the simulator), so concurrent
requests are serialised and SAPIEN is only ever touched from the thread that created it.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import re
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from http import HTTPStatus
from http.server import ThreadingHTTPServer
from pathlib import Path

import numpy as np
import sapien
from PIL import Image

from wsp_data.platforms.maniskill.env import (
    GRIPPER_CLOSED, GRIPPER_OPEN, ManiSkillPlatform, Observation, euler_xyz, to_numpy,
)
from wsp_data.schema import ACTION_DIM, FPS
from wsp_eval.local_http import JsonRequestHandler
from wsp_data.platforms.maniskill.experts import ExpertSource, rotated, task_spec
from wsp_data.platforms.maniskill.skills import SkillScript

PROVENANCE_KIND = "human_teleop"
TOOL = "wsp teleop"
STEP_M = 0.01  # TCP translation per command
YAW_RAD = 0.1  # TCP yaw per command
FINE = 0.25  # step factor of a fine command (Shift + key on the page)
LEASH_M = 0.03  # the commanded TCP target stays within this distance of the actual TCP
IK_TOLERANCE_M = 0.005  # a joint target whose TCP misses the commanded one by more than this is an IK failure
Z_RANGE = (0.0, 0.6)  # commanded TCP height (world z, the table top is 0)
# Replay verification tolerances (measured: the pd_joint_pos replay matches the live rollout exactly).
REPLAY_TOL_Q = 1e-4  # rad / m on joint positions
REPLAY_TOL_POSE = 1e-4  # m on TCP and object positions
FRAME_SCALE = 4  # the live view is served 4× upscaled (nearest)
PAGE = Path(__file__).with_name("teleop_page.html")

MOVES = {"x+": (0, 1), "x-": (0, -1), "y+": (1, 1), "y-": (1, -1), "z+": (2, 1), "z-": (2, -1)}
STEPPING = (*MOVES, "yaw+", "yaw-", "open", "close", "toggle", "hold")
COMMANDS = (*STEPPING, "noop", "reset", "save")  # noop = hold


class TeleopError(RuntimeError):
    """A command or save the session cannot carry out (a client error)."""


class _LiveScript(SkillScript):
    """A `SkillScript` on a rendering `pd_ee_pose` env that keeps every step's observation (the last one with
    its camera frame). Recording is `SkillScript`'s: after each step, the arm controller's IK joint targets
    plus the gripper command."""

    def __init__(self, task: str, objects: tuple[str, ...]):  # SkillScript's own env would not render
        self.platform = ManiSkillPlatform(task, render=True, control_mode="pd_ee_pose", objects=objects)
        self.u = self.platform.u
        self.actions: list[np.ndarray] = []
        self.grip = GRIPPER_OPEN
        self._target: sapien.Pose | None = None
        self.observations: list[Observation] = []
        self.targets: list[np.ndarray] = []  # commanded TCP target per step (world xyz + quaternion wxyz)

    def reset(self, seed: int) -> None:
        self.observations = [self.platform.reset(seed)]
        self.actions, self.targets, self.grip, self._target = [], [], GRIPPER_OPEN, self.tcp

    def _command(self, target: sapien.Pose) -> None:
        rel = self.u.agent.robot.pose.sp.inv() * target
        cmd = np.array([*rel.p, *euler_xyz(rel.q), self.grip], dtype=np.float32)
        ob = self.platform.step(cmd)
        q = to_numpy(self.u.agent.controller.controllers["arm"]._target_qpos[0])
        self.actions.append(np.array([*q, self.grip], dtype=np.float32))
        self.targets.append(np.array([*target.p, *target.q], dtype=np.float32))
        prev = self.observations[-1]
        prev.rgb = prev.mask = None  # only the latest frame is kept
        self.observations.append(ob)
        self._target = target


@dataclass
class TeleopTrajectory:
    """A saved teleoperation trajectory (`load_trajectory`)."""

    path: Path
    task: str
    seed: int
    operator: str
    actions: np.ndarray  # (T, 8) float32 pd_joint_pos stream
    provenance: dict
    commands: np.ndarray  # (T,) str: the command of each step
    ee_targets: np.ndarray  # (T, 7) commanded TCP target, world xyz + quaternion wxyz
    qpos: np.ndarray  # (T+1, 9) live rollout, frame 0 = after reset
    tcp_pose: np.ndarray  # (T+1, 7)
    object_poses: np.ndarray  # (T+1, MAX_OBJECTS, 7), NaN where the task has fewer objects

    @property
    def success(self) -> bool:
        return bool(self.provenance["success"])


def load_trajectory(path: str | Path) -> TeleopTrajectory:
    """Read a trajectory file written by `TeleopSession.save`."""
    path = Path(path)
    with np.load(path, allow_pickle=False) as z:
        actions = z["actions"].astype(np.float32)
        if actions.ndim != 2 or actions.shape[1] != ACTION_DIM:
            raise ValueError(f"{path}: expected (T, {ACTION_DIM}) actions, got {actions.shape}")
        return TeleopTrajectory(
            path=path, task=str(z["task"]), seed=int(z["seed"]), operator=str(z["operator"]), actions=actions,
            provenance=json.loads(str(z["provenance"])), commands=z["commands"], ee_targets=z["ee_targets"],
            qpos=z["qpos"], tcp_pose=z["tcp_pose"], object_poses=z["object_poses"],
        )


def _operator_slug(name: str) -> str:
    slug = re.sub(r"[^A-Za-z0-9.-]+", "-", name.strip()).strip("-.")
    if not slug:
        raise TeleopError(f"operator name {name!r} has no usable characters (letters, digits, '.', '-')")
    return slug[:40]


def _timestamp() -> str:
    now = datetime.now(timezone.utc)
    return now.strftime("%Y%m%dT%H%M%S") + f"{now.microsecond // 1000:03d}Z"


def _snap(v: np.ndarray) -> str | None:
    """A horizontal world direction as the nearest move command (`x+`, `y-`, …)."""
    if np.linalg.norm(v[:2]) < 1e-6:
        return None
    i = int(np.argmax(np.abs(v[:2])))
    return f"{'xy'[i]}{'+' if v[i] > 0 else '-'}"


def _opposite(cmd: str) -> str:
    return cmd[:-1] + ("-" if cmd.endswith("+") else "+")


def screen_keymap(extrinsic: np.ndarray) -> dict[str, str]:
    """Keys → commands with W/S/A/D relative to the camera: W moves away from the viewer, D to the right of
    the image (each snapped to the nearest world axis), R/F up/down, Q/E yaw left/right, Space toggles the
    gripper, H holds for one step, Enter saves."""
    rot = np.asarray(extrinsic, dtype=np.float64)[:3, :3]  # OpenCV world→camera: rows are the camera axes
    right, down, forward = rot[0], rot[1], rot[2]
    flat = np.array([1.0, 1.0, 0.0])
    away, side = _snap((forward - down) * flat), _snap(right * flat)
    if away is None or side is None or away[0] == side[0]:
        away, side = "x+", "y+"
    return {"w": away, "s": _opposite(away), "d": side, "a": _opposite(side), "r": "z+", "f": "z-",
            "q": "yaw+", "e": "yaw-", " ": "toggle", "h": "hold", "Enter": "save"}


class TeleopSession:
    """One operator episode: a live `pd_ee_pose` simulator for `task` at `seed`, the recorded `pd_joint_pos`
    stream, the expert rollout of the same seed, and replay-verified saving. Not thread-safe: `TeleopServer`
    runs every call on one thread."""

    def __init__(self, task: str, seed: int, *, step_m: float = STEP_M, yaw_rad: float = YAW_RAD,
                 expert: bool = True):
        self.spec = task_spec(task)
        self.task, self.seed = self.spec.name, int(seed)
        self.step_m, self.yaw_rad = float(step_m), float(yaw_rad)
        self.live = _LiveScript(self.task, self.spec.objects)
        self._expert = ExpertSource(self.task)
        self._expert_done = False
        self.expert_actions: np.ndarray | None = None
        self.expert_frames: list[np.ndarray] | None = None
        self.commands: list[str] = []
        self.last: dict = {}
        self.keymap: dict[str, str] = {}
        self.reset()
        self.keymap = screen_keymap(self.live.platform.camera_params()[1])
        if expert:
            self.render_expert()

    # -- lifecycle ------------------------------------------------------------------------------
    def close(self) -> None:
        self.live.close()
        self._expert.close()

    @property
    def replayer(self) -> ManiSkillPlatform:
        """The state-only `pd_joint_pos` env that verifies saves (the expert source's own replayer)."""
        return self._expert.replayer

    def render_expert(self) -> list[np.ndarray] | None:
        """The expert rollout of this task and seed (`ExpertSource.trajectory`), rendered once: its frames,
        or None when the scripted expert fails on this seed."""
        if not self._expert_done:
            self._expert_done = True
            self.expert_actions = self._expert.trajectory(self.seed)
            if self.expert_actions is not None:
                with ManiSkillPlatform(self.task, render=True, objects=self.spec.objects) as p:
                    ro = p.replay(self.seed, self.expert_actions)
                self.expert_frames = [o.rgb for o in ro.observations]
        return self.expert_frames

    # -- commands -------------------------------------------------------------------------------
    def reset(self) -> dict:
        """Back to the start of the episode; the recorded stream is discarded."""
        self.live.reset(self.seed)
        self.commands = []
        self.last = {"command": "reset", "ik_failed": False}
        return self.state()

    def command(self, cmd: str, fine: bool = False) -> dict:
        """Apply one command (see `COMMANDS`; `save` is `save()`): every stepping command is one control step."""
        if cmd == "reset":
            return self.reset()
        if cmd == "noop":
            cmd = "hold"
        if cmd not in STEPPING:
            raise TeleopError(f"unknown command {cmd!r}; known: {', '.join(COMMANDS)}")
        s = self.live
        prev = s._target
        scale = FINE if fine else 1.0
        target = prev
        if cmd in MOVES:
            axis, sign = MOVES[cmd]
            p = np.array(prev.p, dtype=np.float64)
            p[axis] += sign * scale * self.step_m
            target = sapien.Pose(self._leash(p), prev.q)
        elif cmd in ("yaw+", "yaw-"):
            target = rotated(prev, [0, 0, 1], (1 if cmd == "yaw+" else -1) * scale * self.yaw_rad)
        elif cmd == "open":
            s.grip = GRIPPER_OPEN
        elif cmd == "close":
            s.grip = GRIPPER_CLOSED
        elif cmd == "toggle":
            s.grip = GRIPPER_CLOSED if s.grip == GRIPPER_OPEN else GRIPPER_OPEN
        s._command(target)
        self.commands.append(cmd)
        reached = self.live.platform.ee_action(s.actions[-1])[:3]
        wanted = (s.u.agent.robot.pose.sp.inv() * target).p
        ik_failed = bool(np.linalg.norm(reached - wanted) > IK_TOLERANCE_M)
        if ik_failed:  # unreachable: the arm held still; forget the target so the next command starts from here
            s._target = prev
        self.last = {"command": cmd, "ik_failed": ik_failed}
        return self.state()

    def _leash(self, p: np.ndarray) -> np.ndarray:
        p[2] = min(max(p[2], Z_RANGE[0]), Z_RANGE[1])
        tcp = np.asarray(self.live.tcp.p, dtype=np.float64)
        d = p - tcp
        n = float(np.linalg.norm(d))
        return tcp + d * (LEASH_M / n) if n > LEASH_M else p

    # -- queries --------------------------------------------------------------------------------
    @property
    def steps(self) -> int:
        return len(self.live.actions)

    def frame(self) -> np.ndarray:
        """The current 128×128 RGB camera frame."""
        return self.live.observations[-1].rgb

    def state(self) -> dict:
        ob = self.live.observations[-1]
        tcp = sapien.Pose(ob.tcp_pose[:3], ob.tcp_pose[3:])
        yaw = math.atan2(*tcp.to_transformation_matrix()[[1, 0], 0])
        return {
            "task": self.task, "seed": self.seed, "instruction": self.spec.instruction,
            "steps": self.steps, "success": bool(ob.success),
            "tcp": [round(float(v), 4) for v in ob.tcp_pose[:3]], "yaw": round(yaw, 4),
            "gripper": "open" if self.live.grip == GRIPPER_OPEN else "closed",
            "gripper_command": float(self.live.grip),
            "last_command": self.last.get("command"), "ik_failed": self.last.get("ik_failed", False),
            "expert_steps": None if self.expert_actions is None else len(self.expert_actions),
            "keymap": self.keymap, "step_m": self.step_m, "yaw_rad": self.yaw_rad, "fps": FPS,
        }

    # -- verification and saving -------------------------------------------------------------------
    def verify(self) -> dict:
        """Replay the recorded stream under `pd_joint_pos` (fresh state-only env, same seed) and compare every
        step with the live rollout: joint positions, TCP pose, object poses, and the final success."""
        actions = self.live.trajectory()
        live = self.live.observations
        p = self.replayer
        obs = [p.reset(self.seed)]
        obs += [p.step(a) for a in actions]

        def err(name: str, sl=slice(None)) -> float:
            a = np.stack([getattr(o, name) for o in obs])[..., sl]
            b = np.stack([getattr(o, name) for o in live])[..., sl]
            d = np.abs(a.astype(np.float64) - b)
            return float(np.nanmax(d)) if np.isfinite(d).any() else 0.0

        e_q, e_tcp, e_obj = err("qpos"), err("tcp_pose", slice(0, 3)), err("object_poses", slice(0, 3))
        success = bool(obs[-1].success)
        verified = (e_q <= REPLAY_TOL_Q and e_tcp <= REPLAY_TOL_POSE and e_obj <= REPLAY_TOL_POSE
                    and success == bool(live[-1].success))
        return {"replay_verified": verified, "success": success, "live_success": bool(live[-1].success),
                "replay_max_qpos_error": e_q, "replay_max_tcp_error_m": e_tcp, "replay_max_object_error_m": e_obj}

    def save(self, out_dir: str | Path, operator: str) -> Path:
        """Verify the recorded stream by replay and write it as `<out>/<task>_seed<seed>_<operator>_<timestamp>.npz`."""
        if self.steps == 0:
            raise TeleopError("nothing recorded yet: send some commands before saving")
        slug = _operator_slug(operator)
        check = self.verify()
        T = self.steps
        provenance = {
            "kind": PROVENANCE_KIND, "operator": operator.strip(), "tool": TOOL, "steps": T,
            "success": check["success"], "replay_verified": check["replay_verified"],
            "task": self.task, "seed": self.seed, "control_mode": "pd_joint_pos",
            "recorded_with": "pd_ee_pose (SkillScript IK joint targets + gripper)",
            "step_m": self.step_m, "yaw_rad": self.yaw_rad, "fps": FPS,
            "replay_max_qpos_error": check["replay_max_qpos_error"],
            "replay_max_tcp_error_m": check["replay_max_tcp_error_m"],
            "replay_max_object_error_m": check["replay_max_object_error_m"],
            "expert_steps": None if self.expert_actions is None else len(self.expert_actions),
            "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        }
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        path = out / f"{self.task}_seed{self.seed}_{slug}_{_timestamp()}.npz"
        live = self.live.observations
        tmp = path.with_name(path.name + ".part")
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f, actions=self.live.trajectory(), task=np.array(self.task), seed=np.int64(self.seed),
                operator=np.array(operator.strip()), provenance=np.array(json.dumps(provenance)),
                commands=np.array(self.commands, dtype=str), ee_targets=np.stack(self.live.targets),
                qpos=np.stack([o.qpos for o in live]), tcp_pose=np.stack([o.tcp_pose for o in live]),
                object_poses=np.stack([o.object_poses for o in live]),
            )
        tmp.replace(path)
        return path


# -- images -------------------------------------------------------------------------------------------
def png_bytes(rgb: np.ndarray, scale: int = FRAME_SCALE) -> bytes:
    img = np.repeat(np.repeat(np.asarray(rgb, dtype=np.uint8), scale, axis=0), scale, axis=1)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def gif_bytes(frames: list[np.ndarray], fps: int = FPS) -> bytes:
    """An endlessly looping GIF of the frames at the control rate (per-frame adaptive palette)."""
    imgs = [Image.fromarray(np.asarray(f, dtype=np.uint8)).quantize(colors=255, method=Image.Quantize.MEDIANCUT)
            for f in frames]
    buf = io.BytesIO()
    imgs[0].save(buf, format="GIF", save_all=True, append_images=imgs[1:], duration=round(1000 / fps), loop=0,
                 disposal=1, optimize=False)
    return buf.getvalue()


# -- server ---------------------------------------------------------------------------------------------
class TeleopServer(ThreadingHTTPServer):
    """The teleoperation page and its API on 127.0.0.1:`port` (0 = any free port) for one `TeleopSession`."""

    daemon_threads = True

    def __init__(self, task: str, seed: int, out: str | Path, operator: str, port: int = 0, **session_kw):
        _operator_slug(operator)
        self.out, self.operator = Path(out), operator
        self.sim = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wsp-teleop-sim")
        self.session: TeleopSession | None = None
        try:
            self.session = self.call(TeleopSession, task, seed, **session_kw)
            frames = self.session.expert_frames
            self.expert_gif = gif_bytes(frames) if frames else None
            self.page = PAGE.read_bytes()
            self.saved: list[str] = []
            self._lock = threading.Lock()
            self._frame = (self.session.steps, png_bytes(self.session.frame()))
            super().__init__(("127.0.0.1", int(port)), _Handler)
        except BaseException:
            self._close_session()
            raise

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}/"

    def call(self, fn, *args, **kwargs):
        """Run `fn` on the simulator thread and wait for it."""
        return self.sim.submit(fn, *args, **kwargs).result()

    def state(self) -> dict:
        st = self.call(self.session.state)
        st.update(operator=self.operator, out=str(self.out), saved=list(self.saved))
        return st

    def command(self, cmd: str, fine: bool = False) -> dict:
        def run():
            st = self.session.command(cmd, fine)
            frame = png_bytes(self.session.frame())
            with self._lock:
                self._frame = (self.session.steps, frame)
            return st

        st = self.call(run)
        st.update(operator=self.operator, out=str(self.out), saved=list(self.saved))
        return st

    def save(self, operator: str | None = None) -> dict:
        operator = (operator or "").strip() or self.operator
        path = self.call(self.session.save, self.out, operator)
        prov = load_trajectory(path).provenance
        self.saved.append(str(path))
        return {"path": str(path), "steps": prov["steps"], "success": prov["success"],
                "replay_verified": prov["replay_verified"], "operator": prov["operator"]}

    def frame_png(self) -> bytes:
        with self._lock:
            return self._frame[1]

    def server_close(self) -> None:
        super().server_close()
        self._close_session()

    def _close_session(self) -> None:
        try:
            if self.session is not None:
                self.call(self.session.close)
                self.session = None
        finally:
            self.sim.shutdown(wait=True)


class _Handler(JsonRequestHandler):
    server: TeleopServer

    def _body(self) -> dict:
        return self._json_body(65536, TeleopError)

    def do_GET(self) -> None:  # noqa: N802
        path = self.path.split("?", 1)[0]
        srv = self.server
        if path in ("/", "/index.html"):
            self._send(200, srv.page, "text/html; charset=utf-8")
        elif path == "/frame.png":
            self._send(200, srv.frame_png(), "image/png")
        elif path == "/expert.gif":
            if srv.expert_gif is None:
                self._json({"error": f"the scripted expert has no successful rollout for seed {srv.session.seed}"},
                           404)
            else:
                self._send(200, srv.expert_gif, "image/gif")
        elif path == "/state":
            self._json(srv.state())
        else:
            self._json({"error": f"no such page {path!r}"}, 404)

    def do_POST(self) -> None:  # noqa: N802
        path = self.path.split("?", 1)[0]
        srv = self.server
        try:
            body = self._body()
            if path == "/save" or (path == "/command" and body.get("cmd") == "save"):
                self._json(srv.save(body.get("operator")))
            elif path == "/command":
                self._json(srv.command(str(body.get("cmd")), bool(body.get("fine", False))))
            elif path == "/reset":
                self._json(srv.command("reset"))
            else:
                self._json({"error": f"no such endpoint {path!r}"}, 404)
        except TeleopError as e:
            self._json({"error": str(e)}, HTTPStatus.BAD_REQUEST)
        except Exception as e:  # noqa: BLE001 - report simulator errors to the page instead of dropping the socket
            self._json({"error": f"{type(e).__name__}: {e}"}, HTTPStatus.INTERNAL_SERVER_ERROR)


# -- command line ---------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    p.add_argument("--task", default="PickCube", help="ManiSkill task (default PickCube)")
    p.add_argument("--seed", type=int, default=0, help="scene seed of the episode (default 0)")
    p.add_argument("--operator", required=True, help="operator name recorded in the provenance (e.g. H1)")
    p.add_argument("--out", type=Path, default=Path("teleop"), help="folder for saved trajectories (default ./teleop)")
    p.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (default 8765; 0 = any free port)")
    p.add_argument("--step", type=float, default=STEP_M, help=f"TCP translation per command, m (default {STEP_M})")
    p.add_argument("--yaw-step", type=float, default=YAW_RAD, help=f"TCP yaw per command, rad (default {YAW_RAD})")
    return p


def run(args: argparse.Namespace) -> int:
    print(f"starting the {args.task} simulator (seed {args.seed}) and rendering the expert rollout …", flush=True)
    try:
        server = TeleopServer(args.task, args.seed, args.out, args.operator, port=args.port, step_m=args.step,
                              yaw_rad=args.yaw_step)
    except (KeyError, TeleopError) as e:
        print(f"error: {e.args[0] if isinstance(e, KeyError) else e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"error: cannot listen on 127.0.0.1:{args.port}: {e}", file=sys.stderr)
        return 2
    print(f"teleoperation page: {server.url}  (operator {args.operator}; trajectories go to {args.out}/; "
          f"Ctrl-C to stop)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
    return 0


def main(argv: list[str] | None = None) -> int:
    p = add_arguments(argparse.ArgumentParser(prog="wsp teleop", description="Teleoperate a ManiSkill task in "
                                              "the browser and record replay-verified source trajectories."))
    return run(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
