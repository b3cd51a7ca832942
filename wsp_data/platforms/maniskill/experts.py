"""Expert source trajectories: one scripted solver per ManiSkill task, built from `skills`.

`TASKS` is the registry of the benchmark's ManiSkill tasks (name → `TaskSpec`). `ExpertSource` scripts a
task at a seed, replays the recorded joint stream under `pd_joint_pos` and keeps it only if the replay
succeeds, so every source trajectory it returns is a verified `pd_joint_pos` success.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import sapien
import trimesh
from mani_skill.examples.motionplanning.base_motionplanner.utils import compute_grasp_info_by_obb, get_actor_obb

from wsp_data.platforms.maniskill.env import ManiSkillPlatform
from wsp_data.platforms.maniskill.skills import SkillScript, verify

FINGER_LENGTH = 0.025
TOOL_LEAN = 0.35  # rad the hand leans forward to hold a tool beyond a vertical hand's reach


@dataclass(frozen=True)
class TaskSpec:
    """A ManiSkill task of the benchmark: its objects (pose/contact columns, in order) and its solver."""

    name: str
    objects: tuple[str, ...]
    instruction: str
    solve: Callable[[SkillScript], None]

    @property
    def target(self) -> str:
        """The dominant object the task manipulates (first listed)."""
        return self.objects[0]


def top_grasp(s: SkillScript, actor: str, yaw: float = 0.0, offset=(0.0, 0.0, 0.0), closing=None) -> sapien.Pose:
    """Top-down grasp on an actor's oriented bounding box (ManiSkill's own grasp construction). `closing`
    picks, among equally wide faces, the finger-closing axis nearest to that direction."""
    obb = get_actor_obb(s.platform.actor(actor))
    hint = s.u.agent.tcp.pose.to_transformation_matrix()[0, :3, 1].cpu().numpy()
    if closing is not None:  # the sign nearest to the wrist's current one keeps joint 7 from winding up
        closing = np.asarray(closing, dtype=np.float64)
        hint = closing if closing @ hint >= 0 else -closing
    info = compute_grasp_info_by_obb(obb, approaching=np.array([0, 0, -1]), target_closing=hint,
                                     depth=FINGER_LENGTH)
    pose = s.u.agent.build_grasp_pose(np.array([0, 0, -1]), info["closing"], info["center"])
    return pose * sapien.Pose(offset, _yaw_q(yaw))


def _yaw_q(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)])


def _xyz(p) -> np.ndarray:
    return np.asarray(p, dtype=np.float64).reshape(-1)[:3]


def _axis(pose: sapien.Pose, i: int) -> np.ndarray:
    """The world direction of a pose's local axis i (0 x, 1 y, 2 z)."""
    return pose.to_transformation_matrix()[:3, i]


def _yaw(pose: sapien.Pose) -> float:
    x = _axis(pose, 0)
    return float(np.arctan2(x[1], x[0]))


def _angle(q) -> float:
    """The rotation angle of a unit quaternion."""
    return 2 * float(np.arccos(min(1.0, abs(float(q[0])))))


def _wrap(angle: float, period: float = 2 * np.pi) -> float:
    return float((angle + period / 2) % period - period / 2)


def _turn_z(v, angle: float) -> np.ndarray:
    """A world vector turned by `angle` about the vertical."""
    c, s_ = np.cos(angle), np.sin(angle)
    return np.array([c * v[0] - s_ * v[1], s_ * v[0] + c * v[1], v[2]])


def rotated(pose: sapien.Pose, axis, angle: float) -> sapien.Pose:
    """`pose` turned by `angle` about a world axis through its own origin (the TCP stays put)."""
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    r = sapien.Pose(q=[np.cos(angle / 2), *(np.sin(angle / 2) * axis)])
    return sapien.Pose(pose.p, (r * sapien.Pose(q=pose.q)).q)


def pick(s: SkillScript, actor: str, lift: float = 0.08, closing=None) -> sapien.Pose:
    """Top-down grasp of an actor and a vertical lift; returns the grasp pose."""
    g = top_grasp(s, actor, closing=closing)
    s.grasp(g)
    s.lift(lift)
    return g


def place_object(s: SkillScript, actor: str, p, turn: float = 0.0, clearance: float = 0.04) -> None:
    """Carry the grasped `actor` so that its origin lands on `p`, turned by `turn` about the vertical, using
    the actual hand-to-object transform; release and back off."""
    obj = s.pose(actor)
    hand_to_obj = s.tcp.inv() * obj
    tcp = sapien.Pose(np.asarray(p, dtype=np.float64), rotated(obj, [0, 0, 1], turn).q) * hand_to_obj.inv()
    s.place(tcp, clearance=clearance)


def clear_closing(s: SkillScript, actor: str, others: tuple[str, ...], prefer, near: float = 0.09) -> np.ndarray:
    """A finger-closing direction for a top grasp on `actor`: across the direction to the nearest of `others`
    when that one is closer than `near` (so no finger comes down on it), else `prefer`."""
    p = s.pose(actor).p
    d = min((s.pose(o).p - p for o in others), key=lambda v: np.linalg.norm(v[:2])) * [1, 1, 0]
    if np.linalg.norm(d) < near:
        return np.array([-d[1], d[0], 0.0]) / np.linalg.norm(d)
    return np.asarray(prefer, dtype=np.float64)


def turn_closing_to(s: SkillScript, direction) -> float:
    """The smallest turn about the vertical (modulo the gripper's 180° symmetry) that brings the fingers'
    closing axis onto `direction`."""
    c = _axis(s.tcp, 1)
    return _wrap(np.arctan2(direction[1], direction[0]) - np.arctan2(c[1], c[0]), np.pi)


def _pose(x) -> sapien.Pose:
    """A batched ManiSkill pose (or a sapien pose) as a sapien pose of the first env."""
    return x if isinstance(x, sapien.Pose) else x.sp


def align_held(s: SkillScript, actor: str, target: sapien.Pose, rounds: int = 4, tol: float = 2e-4,
               speed: float = 0.5) -> None:
    """Bring a grasped actor onto the world pose `target`: move the hand by the measured correction, and
    repeat (up to `rounds` more times) while the actor is off by more than `tol` metres, to take out grasp
    slip and tracking error."""
    for _ in range(rounds + 1):
        fix = target * s.pose(actor).inv()
        if np.linalg.norm(fix.p) < tol and _angle(fix.q) < 10 * tol:
            break
        s.move(fix * s._target, speed=speed, settle=3)


def insert_held(s: SkillScript, actor: str, goal: sapien.Pose, standoff: float, depth: float = 0.0,
                speed: float = 0.3) -> None:
    """Insertion along the actor's local +x: line the grasped actor up `standoff` short of `goal` (a world
    pose of the actor), then slide it in along that axis to `depth` past the goal."""
    lift = max(0.0, goal.p[2] + 0.05 - s._target.p[2])
    s.move(sapien.Pose([0, 0, lift]) * s._target, speed=0.8)
    align_held(s, actor, goal * sapien.Pose([-standoff, 0, 0]))
    axis = _axis(goal, 0)
    s.move(sapien.Pose((standoff + depth) * axis) * s._target, speed=speed)


# -- solvers ------------------------------------------------------------------------------------
def solve_pick_cube(s: SkillScript) -> None:
    g = top_grasp(s, "cube")
    s.grasp(g)
    s.lift(0.05)
    s.move(sapien.Pose(_xyz(s.u.goal_site.pose.p), g.q), speed=0.8)
    s.hold(8)


def solve_stack_cube(s: SkillScript) -> None:
    g = top_grasp(s, "cubeA")
    s.grasp(g)
    s.lift(0.1)
    above_b = _xyz(s.u.cubeB.pose.p) + np.array([0, 0, 2 * float(s.u.cube_half_size[2])])
    offset = above_b - _xyz(s.u.cubeA.pose.p)
    s.place(sapien.Pose(s.tcp.p + offset, g.q), clearance=0.03)
    s.hold(4)


def solve_push_cube(s: SkillScript) -> None:
    q = s.tcp.q
    obj = _xyz(s.u.obj.pose.p)
    goal = _xyz(s.u.goal_region.pose.p)
    s.push(sapien.Pose(obj + [-0.05, 0, 0], q), sapien.Pose(goal + [-0.09, 0, 0.0], q) * sapien.Pose(), speed=0.5)
    s.hold(3)


def solve_pull_cube(s: SkillScript) -> None:
    q = s.tcp.q
    obj = _xyz(s.u.obj.pose.p)
    goal = _xyz(s.u.goal_region.pose.p)
    s.push(sapien.Pose(obj + [0.05, 0, 0], q), sapien.Pose(goal + [0.06, 0, 0], q), speed=0.5)
    s.hold(3)


def solve_place_sphere(s: SkillScript) -> None:
    g = top_grasp(s, "obj", yaw=np.pi / 4)
    s.grasp(g)
    s.lift(0.1)
    goal = _xyz(s.u.bin.pose.p) + np.array([0, 0, 2 * float(np.asarray(s.u.block_half_size).reshape(-1)[2])])
    offset = goal - _xyz(s.u.obj.pose.p)
    s.place(sapien.Pose(s.tcp.p + offset, g.q), clearance=0.03)
    s.hold(4)


def solve_lift_peg_upright(s: SkillScript) -> None:
    # Grasp the peg near its robot-side end, carry it closer to the base, then pitch the hand by ~90° about
    # the closing axis so the peg hangs straight down (fingers end up pointing back at the robot: the other
    # way round exceeds joint 6's range; 87° rather than 90° keeps the pd_ee_pose Euler command off its
    # singularity, gravity settles the rest), stand it on the table and let go.
    peg = s.pose("peg")
    axis = _axis(peg, 0)
    axis = axis if axis[0] >= 0 else -axis
    g = top_grasp(s, "peg")
    s.grasp(sapien.Pose(peg.p - 0.08 * axis, g.q))
    s.lift(0.23)
    s.move(sapien.Pose([-0.2, s._target.p[1], s._target.p[2]], s._target.q))
    s.move(rotated(s._target, [0, 1, 0], 0.485 * np.pi), speed=0.6)
    peg = s.pose("peg")
    bottom = peg.p[2] - float(s.u.peg_half_length) * abs(_axis(peg, 0)[2])
    s.move(sapien.Pose([0, 0, 0.002 - bottom]) * s._target, speed=0.5)
    s.open_gripper()
    s.move(s._target * sapien.Pose([0, 0, -0.05]), speed=0.6)
    s.hold(4)


def solve_poke_cube(s: SkillScript) -> None:
    # Grasp the peg behind its middle (its head then reaches farther), slide it just above the table in line
    # with the cube, then poke the cube forward with the peg's head until the cube sits on the goal.
    u = s.u
    peg = s.pose("peg")
    s.grasp(sapien.Pose(peg.p - 0.06 * _axis(peg, 0), top_grasp(s, "peg").q))
    s.lift(0.008)
    cube, goal = _xyz(u.cube.pose.p), _xyz(u.goal_region.pose.p)
    head = s.pose("peg").p + float(u.peg_half_length) * _axis(s.pose("peg"), 0)
    s.move(sapien.Pose(s._target.p + [0, cube[1] - head[1], 0], s._target.q), speed=0.6)
    travel = goal[0] - 0.015 - float(u.cube_half_size) - head[0]
    s.move(sapien.Pose(s._target.p + [travel, 0, 0], s._target.q), speed=0.4)
    s.hold(10)


def solve_stack_pyramid(s: SkillScript) -> None:
    # Put cube A beside cube B (yaw aligned, on B's free face nearest to A), then cube C across both. Cubes
    # are picked with the fingers clear of close neighbours, and turned in the air so that the fingers close
    # across the A–B line: they never come down between or onto the two cubes.
    half = float(np.asarray(s.u.cube_half_size).reshape(-1)[0])
    a, b, c = s.pose("cubeA"), s.pose("cubeB"), s.pose("cubeC")
    sides = [b * sapien.Pose(d) for d in ([2.5 * half, 0, 0], [-2.5 * half, 0, 0], [0, 2.5 * half, 0],
                                          [0, -2.5 * half, 0])]
    sides = [p for p in sides if np.linalg.norm(p.p[:2] - c.p[:2]) > 4 * half] or sides
    spot = min(sides, key=lambda p: np.linalg.norm(p.p[:2] - a.p[:2])).p
    line = (spot - b.p) / np.linalg.norm(spot - b.p)
    across = np.array([-line[1], line[0], 0.0])
    turn = _wrap(_yaw(b) - _yaw(a), np.pi / 2)  # the smallest turn that aligns A with B
    pick(s, "cubeA", closing=clear_closing(s, "cubeA", ("cubeB", "cubeC"), _turn_z(across, -turn)))
    place_object(s, "cubeA", spot + [0, 0, 0.003], turn=turn_closing_to(s, across))
    a = s.pose("cubeA")
    turn = _wrap(_yaw(b) - _yaw(c), np.pi / 2)
    pick(s, "cubeC", closing=clear_closing(s, "cubeC", ("cubeA", "cubeB"), _turn_z(across, -turn)))
    place_object(s, "cubeC", (a.p + b.p) / 2 + [0, 0, 2 * half + 0.003], turn=turn_closing_to(s, across))
    s.hold(6)


def solve_roll_ball(s: SkillScript) -> None:
    # Flick the ball with the fingers' flat front face (closing axis across the shot) straight at the goal,
    # back off, and watch it roll until it is about the closest to the goal centre.
    ball, goal = s.pose("ball").p, _xyz(s.u.goal_region.pose.p)
    d = (goal - ball) * [1, 1, 0]
    d /= np.linalg.norm(d)
    y = _axis(s.tcp, 1)
    q = rotated(s.tcp, [0, 0, 1], _wrap(np.arctan2(d[1], d[0]) + np.pi / 2 - np.arctan2(y[1], y[0]), np.pi)).q
    s.push(sapien.Pose(ball - 0.07 * d, q), sapien.Pose(ball + 0.03 * d, q), speed=2.5)
    s.move(sapien.Pose(s._target.p - 0.03 * d + [0, 0, 0.06], q))
    best = np.inf
    for _ in range(250 - len(s.actions)):
        dist = float(np.linalg.norm(s.pose("ball").p[:2] - goal[:2]))
        if dist < 0.02 or dist > best + 0.004:
            break
        best = min(best, dist)
        s.hold(1)


def solve_pull_cube_tool(s: SkillScript) -> None:
    # Grasp the L-tool's handle with the hand leaning forward (the cube lies beyond a vertical hand's reach),
    # lift it, lower the hook just beyond the cube (the cube between handle and hook tip), then draw the tool
    # back towards the base so the hook drags the cube along.
    u = s.u
    tool = s.pose("l_shape_tool")
    g = top_grasp(s, "l_shape_tool")
    g = rotated(g, [0, 1, 0], -TOOL_LEAN)  # the handle lies along x: pitch the fingers forward about y
    grip_x = 0.06
    s.grasp(sapien.Pose((tool * sapien.Pose([grip_x, 0, 0])).p, g.q))
    s.lift(0.08)
    cube = s.pose("cube")  # read now: a cube spawned against the hook is pushed out on the first steps
    hook_face = float(u.handle_length - u.hook_length)
    origin = cube.p + [float(u.cube_half_size) + 0.012 - hook_face, -1.3 * float(u.width), 0]
    tcp = sapien.Pose(origin + [grip_x, 0, s._target.p[2]], g.q)
    s.move(tcp, speed=0.8)
    s.move(sapien.Pose([tcp.p[0], tcp.p[1], g.p[2] + 0.004], g.q), speed=0.5)
    base = _xyz(u.agent.robot.pose.p)
    reach = np.sqrt(max(0.45 ** 2 - (cube.p[1] - base[1]) ** 2, 0.0))  # pull the cube to 0.45 m of the base
    s.move(sapien.Pose(s._target.p - [cube.p[0] - (base[0] + reach), 0, 0], g.q), speed=0.5)
    s.hold(4)


def solve_peg_insertion_side(s: SkillScript) -> None:
    # Grasp the peg on its white half, lift it, line it up 1 cm in front of the hole (closing the loop on the
    # peg's measured pose), then slide it in along the hole axis.
    u = s.u
    half = float(u.peg_half_sizes[0, 0])
    peg = s.pose("peg")
    g = top_grasp(s, "peg")
    s.grasp(sapien.Pose((peg * sapien.Pose([-max(0.05, half / 2 + 0.01), 0, 0])).p, g.q))
    s.lift(0.1)
    insert_held(s, "peg", _pose(u.goal_pose), standoff=half + 0.01, depth=0.02)
    s.hold(3)


def solve_plug_charger(s: SkillScript) -> None:
    # Grasp the charger's base (hand pitched 15° back, as in ManiSkill's own solution), lift it, line its prongs
    # up 5 cm in front of the receptacle and push them home.
    u = s.u
    base = _pose(u.charger_base_pose)
    obb = trimesh.primitives.Box(extents=2 * np.asarray(u._base_size), transform=base.to_transformation_matrix())
    info = compute_grasp_info_by_obb(obb, approaching=np.array([0, 0, -1]), target_closing=_axis(s.tcp, 1),
                                     depth=FINGER_LENGTH)
    g = u.agent.build_grasp_pose(np.array([0, 0, -1]), info["closing"], info["center"])
    g = g * sapien.Pose(q=[np.cos(np.pi / 24), 0, np.sin(np.pi / 24), 0])
    s.move(sapien.Pose([*g.p[:2], max(s._target.p[2], 0.2)], g.q))  # over the receptacle, not through it
    s.grasp(g, clearance=0.05)
    s.lift(0.06)
    insert_held(s, "charger", _pose(u.goal_pose), standoff=0.05, speed=0.2)
    s.hold(3)


TASKS: dict[str, TaskSpec] = {t.name: t for t in (
    TaskSpec("PickCube", ("cube",), "pick up the red cube and move it to the green goal", solve_pick_cube),
    TaskSpec("StackCube", ("cubeA", "cubeB"), "stack the red cube on the green cube", solve_stack_cube),
    TaskSpec("PushCube", ("obj",), "push the cube to the goal region", solve_push_cube),
    TaskSpec("PullCube", ("obj",), "pull the cube to the goal region", solve_pull_cube),
    TaskSpec("PlaceSphere", ("obj", "bin"), "place the sphere into the bin", solve_place_sphere),
    TaskSpec("LiftPegUpright", ("peg",), "lift the peg and stand it upright", solve_lift_peg_upright),
    TaskSpec("PokeCube", ("peg", "cube"), "use the peg to poke the cube into the goal region", solve_poke_cube),
    TaskSpec("RollBall", ("ball",), "roll the ball into the goal region", solve_roll_ball),
    TaskSpec("PullCubeTool", ("l_shape_tool", "cube"), "use the L-shaped tool to pull the cube closer",
             solve_pull_cube_tool),
    TaskSpec("StackPyramid", ("cubeA", "cubeB", "cubeC"),
             "put the red cube next to the green cube and stack the blue cube on top of both", solve_stack_pyramid),
    TaskSpec("PegInsertionSide", ("peg", "box"), "insert the peg into the hole in the box",
             solve_peg_insertion_side),
    TaskSpec("PlugCharger", ("charger", "receptacle"), "plug the charger into the receptacle", solve_plug_charger),
)}


def task_spec(name: str) -> TaskSpec:
    if name not in TASKS:
        raise KeyError(f"unknown ManiSkill task {name!r}; known: {', '.join(sorted(TASKS))}")
    return TASKS[name]


class ExpertSource:
    """Scripted, replay-verified expert trajectories for one task (state-only envs, no rendering)."""

    def __init__(self, task: str):
        self.spec = task_spec(task)
        self.script = SkillScript(task, self.spec.objects)
        self.replayer = ManiSkillPlatform(task, render=False, objects=self.spec.objects)

    def close(self) -> None:
        self.script.close()
        self.replayer.close()

    def scripted(self, seed: int) -> np.ndarray | None:
        """The scripted (T, 8) joint stream for `seed`, not yet replayed (None when the script fails)."""
        self.script.reset(seed)
        try:
            self.spec.solve(self.script)
        except Exception:  # noqa: BLE001 - an unsolvable seed (IK or geometry failure) is just a miss
            return None
        return self.script.trajectory()

    def trajectory(self, seed: int) -> np.ndarray | None:
        """The verified (T, 8) joint stream for `seed`, or None when the script or its replay fails."""
        actions = self.scripted(seed)
        return actions if actions is not None and verify(self.replayer, seed, actions) else None
