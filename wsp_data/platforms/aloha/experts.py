"""Scripted expert sources for ALOHA: per task a closed-loop script planned in end-effector space (per arm the
grip point's position, pitch below the horizon and roll about the approach axis, and the gripper command),
turned into joint targets by the arms' closed-form inverse kinematics and recorded as the native 14-D stream.

The ViperX 300s is a 6-joint arm whose links all lie in the vertical plane through the waist axis while its
forearm roll is 0; the scripts keep that joint at 0 (its actuator, kp 10 against a frictionloss of 30, barely
tracks), so each arm has 5 degrees of freedom: the grip point's position, pitch and roll (the heading follows
the waist). A script runs on the expert's unrendered replayer and reads privileged state (object poses) between
segments; the recorded stream is then replayed from the same scene, and returned only if that replay succeeds.

`TASKS` is the registry of the 8 ALOHA tasks (`env.TASK_LIST`). `AlohaExpertSource(task).trajectory(seed)`
returns the verified stream (20 Hz, at most `MAX_STEPS`) or None.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wsp_data.platforms.aloha.env import HOME, OBJECTS, TCP_X, AlohaPlatform, aloha_task

MAX_STEPS = 160  # 8 s at 20 Hz
V = np.pi / 2  # pitch of a vertical (top-down) grasp
ARM_NAMES = ("left", "right")  # `Script.go`'s keywords
PUSH_PITCH, PUSH_HEIGHT = V, 0.028  # push_cube's hand: pitch, grip point height (fingertips 4 mm up)
PUSH_DISTANCE, PUSH_STEPS = 0.13, 20  # m the hand moves along −x while pushing (the cube ~1.5 cm less)
PEG_START, PEG_END, PEG_STEPS = 0.15, 0.09, 16  # peg centre along the socket axis from its centre (m); the pin
PEG_GAIN = 0.5  # ends 0.04 from the socket centre, the peg's half length is 0.06: contact from 0.10 inwards
FINGERTIP = 0.1537 - TCP_X  # m from the grip point to the fingertips
TIP_CLEARANCE = 0.004  # m: fingertips above the table at a grasp (pressed on it, they cannot slide closed)
STACK_PITCH = np.deg2rad(75)  # stack_cubes carries tilted: vertical, a far green cube is out of reach at carry height
HOLD = 4  # steps held at the end of a script, so success is recorded at rest
# arm geometry (vx300s_*.xml): shoulder pivot above the base, upper arm (with its elbow offset), forearm to the
# wrist pivot, wrist pivot to the grip point
_SHOULDER_Z = 0.079 + 0.04805
_UPPER = np.hypot(0.05955, 0.3)
_UPPER_ELEVATION = np.arctan2(0.3, 0.05955)
_FOREARM = 0.2 + 0.1
_HAND = 0.069744 + TCP_X
HOME_PITCH = -(HOME[1] + HOME[2] + HOME[4])  # the home pose's grip axis points 0.1 rad up


class ArmIK:
    """Closed-form inverse kinematics of one arm with its forearm roll held at 0."""

    def __init__(self, p: AlohaPlatform, arm: int):
        b = p.model.body(f"vx300s_{ARM_NAMES[arm]}").id  # fixed bases: any forwarded state holds their pose
        self.base, self.R = np.array(p.data.xpos[b]), np.array(p.data.xmat[b]).reshape(3, 3)

    def heading(self, pos: np.ndarray) -> float:
        """World yaw (rad) of the arm's vertical plane through `pos`."""
        d = np.asarray(pos) - self.base
        return float(np.arctan2(d[1], d[0]))

    def joints(self, pos: np.ndarray, pitch: float, roll: float) -> np.ndarray:
        """The 6 joint targets (rad) that put the grip point at `pos` (world, m), its approach axis `pitch` rad
        below the horizon and rolled by `roll` rad (elbow up; the nearest reach when out of range)."""
        t = self.R.T @ (np.asarray(pos, dtype=np.float64) - self.base)
        r, z = np.hypot(t[0], t[1]), t[2] - _SHOULDER_Z
        rw, zw = r - _HAND * np.cos(pitch), z + _HAND * np.sin(pitch)  # the wrist pivot
        d = max(np.hypot(rw, zw), 1e-6)
        up = np.arctan2(zw, rw) + np.arccos(np.clip((_UPPER ** 2 + d ** 2 - _FOREARM ** 2) / (2 * _UPPER * d), -1, 1))
        ex, ez = _UPPER * np.cos(up), _UPPER * np.sin(up)  # the elbow
        fore = np.arctan2(zw - ez, rw - ex)  # forearm elevation
        shoulder = _UPPER_ELEVATION - up
        return np.array([np.arctan2(t[1], t[0]), shoulder, -fore - shoulder, 0.0, pitch + fore, roll])


@dataclass(frozen=True)
class Hand:
    """One arm's end-effector command: grip point (world, m), pitch and roll (rad), gripper g (1 open)."""

    pos: np.ndarray
    pitch: float
    roll: float
    grip: float


def lerp(a: Hand, b: Hand, f: float) -> Hand:
    """The hand pose a fraction `f` of the way from `a` to `b` (position, pitch, roll and grip alike)."""
    return Hand(a.pos + f * (b.pos - a.pos), a.pitch + f * (b.pitch - a.pitch), a.roll + f * (b.roll - a.roll),
                a.grip + f * (b.grip - a.grip))


def _wrap_half_pi(a: float) -> float:
    """An angle modulo π, in [−π/2, π/2): a parallel-jaw grasp is symmetric under a half turn."""
    return (a + np.pi / 2) % np.pi - np.pi / 2


def _yaw(R: np.ndarray) -> float:
    return float(np.arctan2(R[1, 0], R[0, 0]))


class OutOfTime(Exception):
    """The script used up MAX_STEPS."""


class Script:
    """Both arms' end-effector commands, stepped in lockstep on a platform; records the joint stream it sends."""

    def __init__(self, p: AlohaPlatform, seed: int, placements: dict[str, np.ndarray] | None = None):
        self.p = p
        self.observation = p.reset(seed, placements)
        self.ik = (ArmIK(p, 0), ArmIK(p, 1))
        home = [self.ik[k].base + self.ik[k].R @ self._home_reach() for k in (0, 1)]
        self.hand = [Hand(home[k], HOME_PITCH, 0.0, 1.0) for k in (0, 1)]  # IK of these = HOME
        self.actions: list[np.ndarray] = []
        self.max_steps = MAX_STEPS  # T3's operator models (`t3.OperatorScript`) get a larger budget

    @staticmethod
    def _home_reach() -> np.ndarray:
        s, e, w = HOME[1], HOME[2], HOME[1] + HOME[2] + HOME[4]
        up, fore = _UPPER_ELEVATION - s, -(s + e)
        return np.array([_UPPER * np.cos(up) + _FOREARM * np.cos(fore) + _HAND * np.cos(w), 0,
                         _SHOULDER_Z + _UPPER * np.sin(up) + _FOREARM * np.sin(fore) - _HAND * np.sin(w)])

    # -- primitives ----------------------------------------------------------------------------------
    def act(self) -> None:
        if len(self.actions) >= self.max_steps:
            raise OutOfTime
        a = self.command(self.hand)
        self.actions.append(a)
        self.observation = self.p.step(a)

    def command(self, hands: list[Hand]) -> np.ndarray:
        """The 14-D joint-target action of both hands' end-effector commands (inverse kinematics)."""
        return np.concatenate([np.append(self.ik[k].joints(h.pos, h.pitch, h.roll), h.grip)
                               for k, h in enumerate(hands)]).astype(np.float32)

    def duration(self, steps: int) -> int:
        """The actions a segment planned as `steps` actions takes (the expert: as planned; T3's operator models
        stretch or shrink it)."""
        return steps

    def go(self, steps: int, left: dict | None = None, right: dict | None = None) -> None:
        """Move both hands to new commands (fields of `Hand` to change) over `steps` actions, smoothly."""
        start = list(self.hand)
        goal = [replace(h, **{k: np.asarray(v, dtype=np.float64) if k == "pos" else float(v) for k, v in c.items()})
                if c else h for h, c in zip(start, (left, right))]
        for i in range(1, steps + 1):
            f = i / steps
            f = f * f * (3 - 2 * f)
            self.hand = [lerp(a, b, f) for a, b in zip(start, goal)]
            self.act()

    def hold(self, steps: int) -> None:
        for _ in range(steps):
            self.act()

    def obj(self, name: str) -> np.ndarray:
        return self.p.object_pose(name)[:3]

    def tcp(self, arm: int) -> np.ndarray:
        return self.p.tcp(arm)[0]

    def grasp_roll(self, arm: int, pos: np.ndarray, axis_yaw: float) -> float:
        """Roll of a vertical grasp at `pos` whose fingers close along world yaw `axis_yaw`: of the rolls a half
        turn apart (a parallel jaw is symmetric), the one nearest the hand's current roll (no wrist flip)."""
        now = self.hand[arm].roll
        return now + _wrap_half_pi(self.ik[arm].heading(pos) + np.pi / 2 - axis_yaw - now)

    def pick(self, picks: dict[int, tuple[np.ndarray, float]], above: float = 0.08, steps: int = 16) -> None:
        """Vertical grasps, all arms at once: {arm: (grip point, closing-axis yaw)}: over the point, down, close."""
        plan = {ARM_NAMES[a]: (c, self.grasp_roll(a, c, yaw)) for a, (c, yaw) in picks.items()}
        self.go(steps, **{n: {"pos": c + [0, 0, above], "pitch": V, "roll": r} for n, (c, r) in plan.items()})
        self.go(8, **{n: {"pos": c} for n, (c, _) in plan.items()})
        self.go(5, **{n: {"grip": 0.0} for n in plan})
        self.hold(1)

    def grip_point(self, name: str, along: float = 0.0) -> np.ndarray:
        """Where a vertical grasp of `name` closes: over its centre (shifted `along` its x axis, m), the fingertips
        `TIP_CLEARANCE` above the table or 1 cm above the centre, whichever is higher."""
        c = self.obj(name) + along * self.p.body_rotation(name)[:, 0]
        c[2] = max(c[2] + 0.01, TIP_CLEARANCE + FINGERTIP)
        return c


def cube_yaw(p: AlohaPlatform, name: str) -> float:
    """Yaw of an object's x axis (rad)."""
    return _yaw(p.body_rotation(name))


# -- task scripts -----------------------------------------------------------------------------------------
def lift_cube(s: Script) -> None:
    s.pick({1: (s.grip_point("red_cube"), cube_yaw(s.p, "red_cube") + np.pi / 2)})
    s.go(14, right={"pos": s.hand[1].pos + [0, 0, 0.19]})


def push_cube(s: Script) -> None:
    """The right hand, open and vertical with its fingers closing along x (one before, one behind the cube), comes
    down around the cube and pushes it 13 cm along −x with the rear finger's flat, vertical inner face, following
    the cube's y so that it pushes through its centre. (The fingers' outer faces are tapered: at any pitch they
    meet the cube's top edge and jam it against the table.)"""
    c = s.obj("red_cube")
    start = c + [0, 0, PUSH_HEIGHT - c[2]]
    s.go(16, right={"pos": start + [0, 0, 0.08], "pitch": PUSH_PITCH, "roll": s.grasp_roll(1, start, 0.0)})
    s.go(8, right={"pos": start})
    n = s.duration(PUSH_STEPS)
    for i in range(1, n + 1):
        f = i / n
        pos = start - [PUSH_DISTANCE * f * f * (3 - 2 * f), 0, 0]
        pos[1] = s.obj("red_cube")[1]
        s.hand[1] = replace(s.hand[1], pos=pos, roll=s.grasp_roll(1, pos, 0.0))
        s.act()
    s.go(8, right={"pos": s.hand[1].pos + [0, 0, 0.08]})


def transfer(s: Script, giver: int) -> None:
    """`giver` picks the cube, brings it to the middle tilted 60°; the other hand, horizontal with its fingers
    closing vertically, takes it from the giver's far side; the giver lets go and backs off."""
    taker = 1 - giver
    side = 1.0 if giver == 1 else -1.0  # the giver's side of the table (x sign)
    g, t = ARM_NAMES[giver], ARM_NAMES[taker]
    s.pick({giver: (s.grip_point("red_cube"), cube_yaw(s.p, "red_cube") + np.pi / 2)})
    meet = np.array([0.0, 0.5, 0.22])
    s.go(18, **{g: {"pos": meet + [side * 0.02, 0, 0], "pitch": np.deg2rad(60), "roll": 0.0},
                t: {"pos": meet + [-side * 0.12, 0, 0], "pitch": 0.0, "roll": np.pi / 2}})
    s.hold(2)
    c = s.obj("red_cube")
    s.go(12, **{t: {"pos": c + [side * 0.015, 0, 0]}})
    s.go(5, **{t: {"grip": 0.0}})
    s.go(4, **{g: {"grip": 1.0}})
    s.go(10, **{g: {"pos": s.hand[giver].pos + [side * 0.1, 0, 0.03]}})
    s.go(8, **{t: {"pos": s.hand[taker].pos + [-side * 0.06, 0, 0]}})


def place_on(s: Script, name: str, goal_xy: np.ndarray, bottom: float, pitch: float = V) -> None:
    """With `name` held in the right hand: carry it over `goal_xy`, lower its bottom to `bottom` (m), release."""
    lift = s.hand[1].pos + [0, 0, 0.12]
    s.go(10, right={"pos": lift})
    offset = s.tcp(1) - s.obj(name)
    over = np.array([*(goal_xy + offset[:2]), lift[2]])
    s.go(18, right={"pos": over, "pitch": pitch, "roll": s.grasp_roll(1, over, cube_yaw(s.p, name) + np.pi / 2)})
    s.hold(2)
    err = goal_xy - s.obj(name)[:2]  # closed loop: correct the carry's tracking and in-hand offset
    down = s.hand[1].pos + [err[0], err[1], 0]
    down[2] += bottom + OBJECTS[name].rest_z - s.obj(name)[2]
    s.go(10, right={"pos": down})
    s.go(4, right={"grip": 1.0})
    s.go(8, right={"pos": down + [0, 0, 0.08]})


def cube_in_bin(s: Script) -> None:
    s.pick({1: (s.grip_point("red_cube"), cube_yaw(s.p, "red_cube") + np.pi / 2)})
    place_on(s, "red_cube", s.obj("bin")[:2], 0.06, pitch=np.deg2rad(60))


def stack_cubes(s: Script) -> None:
    s.pick({1: (s.grip_point("red_cube"), cube_yaw(s.p, "red_cube") + np.pi / 2)})
    g = s.obj("green_cube")
    place_on(s, "red_cube", g[:2], g[2] + OBJECTS["green_cube"].rest_z + 0.004, pitch=STACK_PITCH)


def two_arm_lift(s: Script) -> None:
    yaw = cube_yaw(s.p, "bar") + np.pi / 2
    s.pick({0: (s.grip_point("bar", -0.11), yaw), 1: (s.grip_point("bar", 0.11), yaw)})
    s.go(16, left={"pos": s.hand[0].pos + [0, 0, 0.15]}, right={"pos": s.hand[1].pos + [0, 0, 0.15]})


def _axis(p: AlohaPlatform, name: str, toward: float) -> np.ndarray:
    """An object's x axis (world), signed to point along world x `toward` (±1)."""
    a = p.body_rotation(name)[:, 0]
    return a if a[0] * toward >= 0 else -a


def peg_insertion(s: Script) -> None:
    """Both hands pick (left: the socket, right: the peg, each at its middle), lift them to face each other along
    x, then the right hand servoes the peg onto the socket's axis (measured each step) and pushes it in until it
    presses on the pin."""
    p = s.p
    s.pick({0: (s.grip_point("socket"), cube_yaw(p, "socket") + np.pi / 2),
            1: (s.grip_point("peg"), cube_yaw(p, "peg") + np.pi / 2)})
    meet = np.array([-0.08, 0.5, 0.18])
    lo, ro = s.tcp(0) - s.obj("socket"), s.tcp(1) - s.obj("peg")  # in-hand offsets
    left, right = meet + lo, meet + [PEG_START, 0, 0] + ro
    s.go(20, left={"pos": left, "roll": s.grasp_roll(0, left, np.pi / 2)},
         right={"pos": right, "roll": s.grasp_roll(1, right, np.pi / 2)})
    s.hold(2)
    for depth in np.concatenate([np.full(6, PEG_START), np.linspace(PEG_START, PEG_END, PEG_STEPS)]):
        a_s, a_p = _axis(p, "socket", 1.0), _axis(p, "peg", 1.0)
        err = s.obj("socket") + depth * a_s - s.obj("peg")
        turn = np.arctan2(a_s[1], a_s[0]) - np.arctan2(a_p[1], a_p[0])
        h = s.hand[1]
        s.hand[1] = replace(h, pos=h.pos + np.clip(PEG_GAIN * err, -0.01, 0.01), roll=h.roll - PEG_GAIN * turn)
        s.act()


SCRIPTS = {"transfer_cube": lambda s: transfer(s, 1), "hand_over": lambda s: transfer(s, 0),
           "lift_cube": lift_cube, "push_cube": push_cube, "cube_in_bin": cube_in_bin, "stack_cubes": stack_cubes,
           "two_arm_lift": two_arm_lift, "peg_insertion": peg_insertion}


def script_stream(p: AlohaPlatform, task: str, seed: int, placements: dict[str, np.ndarray] | None = None
                  ) -> np.ndarray | None:
    """Run `task`'s script on `p` from scene `seed` (with `placements`); the recorded stream, or None when it ran
    out of time."""
    s = Script(p, seed, placements)
    try:
        SCRIPTS[task](s)
        s.hold(HOLD)
    except OutOfTime:
        return None
    return np.stack(s.actions)


class AlohaExpertSource:
    """Scripted, verified expert streams for one ALOHA task."""

    def __init__(self, task: str):
        self.spec = aloha_task(task)
        self.replayer = AlohaPlatform(task, render=False, objects=self.spec.objects)
        self._cache: dict[int, np.ndarray | None] = {}

    def close(self) -> None:
        self.replayer.close()

    def scripted(self, seed: int) -> np.ndarray | None:
        """The scripted (T, 14) joint-target stream for scene `seed`, not yet replayed (None: out of time)."""
        return script_stream(self.replayer, self.spec.name, seed)

    def trajectory(self, seed: int) -> np.ndarray | None:
        """The (T, 14) joint-target stream that solves the task at scene `seed`, or None if its replay fails."""
        if seed not in self._cache:
            actions = self.scripted(seed)
            ok = actions is not None and self.replayer.replay(seed, actions).success
            self._cache[seed] = actions if ok else None
        return self._cache[seed]
