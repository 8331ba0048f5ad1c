"""Grips chosen, not assumed: where a robot of a cell takes a block, and what it carries.

A grip is on a face of the block free of contacts with the blocks present when it is taken
(faces free in the finished assembly first: no later block lands on them; a block placed
while another is held must not land on its grip face or hit its gripper,
:meth:`GripChooser.in_the_way`), at the face's centroid (the tool centre point, TCP). The
tool frame: z into the face (the face's outward normal reversed), x the face's in-plane
direction closest to world up (the world x axis on a horizontal face), y = z x x. The
gripper is a box of the tool's size behind the TCP (its far face on the face gripped,
centred on the TCP), which must not touch a block present (python-fcl against their convex
hulls, as the insertion check); the TCP is within the robot's reach of its base. Of the
faces that pass, a robot takes the one facing its base most; a block it will hold, the one
whose hold torque is least (its block's weight about the TCP and its tool's, what it carries
at least: held still, the robot carries its block's weight and what leans on it), so that
the payload left for what leans on the block is most.

What the robot carries: the block's need (force F at the TCP, torque M about it, from the
check) and its tool's weight, m_t g at the box centre c: F_r = F - m_t g, M_r = M +
(c - p) x (-m_t g), within the robot's payload. The check bounds the block's need by the
payload less what the tool takes in the worst case (|F| <= payload - m_t |g|, |M| <=
payload torque - m_t |g| |c - p|), so a wrench it accepts is within the payload.

What the placing robot carries to the block's pose (:func:`carry_wrench`, the place action):
the block's whole weight m g at its centre of mass b, nothing else bearing it, and the tool's:
F_r = -(m + m_t) g, M_r = (b - p) x (-m g) + (c - p) x (-m_t g). A robot grips a block to
place it only on a face where that is within its payload (:meth:`GripChooser.choose`
``carry``): faces where the block hangs less off the TCP (a top face, the tool axis along
gravity) pass where a side face's torque does not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import fcl
import numpy as np
from scipy.spatial.transform import Rotation

from ..cell import Cell, CellError, Robot
from ..geometry.block import PosedBlock, pose_blocks
from ..geometry.insertion import present_pieces
from ..rbe.model import Grip
from ..scene import Scene
from .assembly import Assembly
from .kinematics import load_arm, solve_ik

#: A face is in contact when an interface lies in its plane within this share of the
#: block's size and their normals are within CONTACT_COS.
CONTACT_DISTANCE = 1e-2
CONTACT_COS = math.cos(math.radians(5.0))
#: The gripper box stands off the face by this (m), so that touching its own face is no
#: collision; the other blocks are shrunk by it, so that a box touching one (a footing's top
#: beside the face gripped) is none either.
STANDOFF = 1e-3
#: How far (m) the TCP backs off along the face normal before it grips (the pre-grip frame).
PRE_GRIP = 0.1


@dataclass(frozen=True)
class GripFrame:
    """A grip of ``block``: the TCP ``point`` (world), the tool frame's axes (``rotation``,
    columns x, y, z in world), the face's outward ``normal`` and index."""

    block: str
    face: int
    point: np.ndarray
    rotation: np.ndarray
    normal: np.ndarray

    @property
    def quaternion(self) -> np.ndarray:
        """The tool frame's orientation (x, y, z, w)."""
        return Rotation.from_matrix(self.rotation).as_quat()

    def shifted(self, offset) -> "GripFrame":
        """This frame moved by ``offset`` (m, world)."""
        return GripFrame(self.block, self.face, self.point + np.asarray(offset, dtype=float),
                         self.rotation, self.normal)


def tool_box_pose(robot: Robot, grip: GripFrame) -> tuple[np.ndarray, np.ndarray]:
    """(centre, rotation) of ``robot``'s gripper box at ``grip``: behind the TCP, along the
    face's outward normal."""
    depth = robot.tool.box[2]
    return grip.point + grip.normal * (0.5 * depth + STANDOFF), grip.rotation


def robot_grip(grip: GripFrame, robot: Robot) -> Grip:
    """The check's grip of ``grip`` held by ``robot``: the payload less the tool's worst
    share (:mod:`rbe_ros.analysis.grips`)."""
    weight = robot.tool.mass * 9.81
    centre, _ = tool_box_pose(robot, grip)
    arm = float(np.linalg.norm(centre - grip.point))
    return Grip(grip.block, grip.point, max(robot.payload_force - weight, 0.0),
                max(robot.payload_torque - weight * arm, 0.0))


@dataclass(frozen=True)
class RobotWrench:
    """What a robot applies at its TCP: to the block alone (world axes) and with its tool's
    weight (world and tool axes), and its use of the payload (the larger ratio)."""

    force_world: np.ndarray      # on the block, N
    torque_world: np.ndarray     # about the TCP, N m
    force_robot: np.ndarray      # with the tool's weight, world axes
    torque_robot: np.ndarray
    force_tool: np.ndarray       # the same in tool axes
    torque_tool: np.ndarray
    utilisation: float


def robot_wrench(robot: Robot, grip: GripFrame, force, torque, gravity) -> RobotWrench:
    """``robot``'s wrench at ``grip`` when the block needs ``force`` and ``torque`` (about the
    TCP, world), its tool's weight included."""
    force, torque = np.asarray(force, dtype=float), np.asarray(torque, dtype=float)
    carry = -robot.tool.mass * np.asarray(gravity, dtype=float)
    centre, _ = tool_box_pose(robot, grip)
    f_r = force + carry
    m_r = torque + np.cross(centre - grip.point, carry)
    rt = grip.rotation.T
    use = max(_ratio(np.linalg.norm(f_r), robot.payload_force),
              _ratio(np.linalg.norm(m_r), robot.payload_torque))
    return RobotWrench(force, torque, f_r, m_r, rt @ f_r, rt @ m_r, use)


def carry_wrench(robot: Robot, grip: GripFrame, block: PosedBlock, gravity) -> RobotWrench:
    """``robot``'s wrench carrying ``block`` by ``grip`` (at the block's placed pose, which
    the carry only translates): its whole weight at its centre of mass, the tool's included."""
    weight = block.mass * np.asarray(gravity, dtype=float)
    return robot_wrench(robot, grip, -weight, np.cross(block.centroid - grip.point, -weight),
                        gravity)


#: Digits (N m) to which hold torques are ranked: faces alike by symmetry tie to the
#: rounding of their geometry and are taken by the base's direction.
TORQUE_DIGITS = 6


def hold_torque(robot: Robot, grip: GripFrame, block: PosedBlock, gravity) -> float:
    """The torque (N m, rounded to TORQUE_DIGITS) ``robot`` needs at least to hold ``block``
    still by ``grip``: its block's weight about the TCP and its tool's (the carry wrench's;
    what leans on the block adds)."""
    return round(float(np.linalg.norm(carry_wrench(robot, grip, block, gravity).torque_robot)),
                 TORQUE_DIGITS)


def wrench_need(w: RobotWrench, robot: Robot) -> str:
    """A robot's wrench with the tool's weight against its payload, in words."""
    return (f"|F| {np.linalg.norm(w.force_robot):.0f} N, |M| {np.linalg.norm(w.torque_robot):.0f}"
            f" N m with its gripper (payload {robot.payload_force:g} N, "
            f"{robot.payload_torque:g} N m)")


def _ratio(value: float, cap: float) -> float:
    return float(value / cap) if cap > 0 else (0.0 if value < 1e-9 else math.inf)


class GripChooser:
    """The grips of the blocks of an assembly (its finished state) for the robots of a cell:
    each face with the blocks it touches there, found once; each choice by the blocks near
    the block that are present."""

    def __init__(self, assembly: Assembly, cell: Cell):
        self.assembly, self.cell = assembly, cell
        self._touching: dict[int, list[tuple[np.ndarray, np.ndarray, str]]] = {}
        for it in assembly.interfaces:
            centre = it.points.mean(axis=0)
            a, b = assembly.blocks[it.a].id, assembly.blocks[it.b].id
            self._touching.setdefault(it.a, []).append((it.frame.n, centre, b))
            self._touching.setdefault(it.b, []).append((-it.frame.n, centre, a))
        self._faces: dict[str, list[tuple[GripFrame, frozenset[str]]]] = {}
        self._chosen: dict[tuple, tuple[GripFrame | None, str]] = {}
        # a gripper box reaches at most its diagonal beyond the block's bounding box
        self._reach = max((float(np.linalg.norm(r.tool.box)) for r in cell.robots),
                          default=0.0) + 2 * STANDOFF

    @cached_property
    def _boxes(self) -> np.ndarray:
        return np.array([b.aabb for b in self.assembly.blocks])

    def near(self, block: str) -> frozenset[str]:
        """The other blocks a gripper at ``block`` could touch (bounding boxes apart by less
        than a gripper box's diagonal)."""
        box = self._boxes[self.assembly.index[block]]
        gap = np.maximum(0.0, np.maximum(self._boxes[:, 0] - box[1], box[0] - self._boxes[:, 1]))
        close = np.linalg.norm(gap, axis=1) <= self._reach
        return frozenset(b.id for b, c in zip(self.assembly.blocks, close)
                         if c and b.id != block)

    def faces(self, block: str) -> list[tuple[GripFrame, frozenset[str]]]:
        """The grips of ``block`` on each of its faces, with the blocks touching that face in
        the finished assembly."""
        found = self._faces.get(block)
        if found is None:
            found = self._faces[block] = self._all_faces(block)
        return found

    def _all_faces(self, block: str) -> list[tuple[GripFrame, frozenset[str]]]:
        k = self.assembly.index[block]
        b = self.assembly.blocks[k]
        touching = self._touching.get(k, [])
        up = -self.assembly.gravity / (np.linalg.norm(self.assembly.gravity) or 1.0)
        out = []
        for f, (n, origin, u, v, outline) in enumerate(zip(
                b.face_normals, b.face_origins, b.face_us, b.face_vs, b.face_outlines)):
            on = frozenset(other for m, c, other in touching if float(n @ m) > CONTACT_COS
                           and abs(float(n @ (c - origin))) < CONTACT_DISTANCE * b.size)
            c2 = outline.centroid
            point = origin + u * c2.x + v * c2.y
            z = -n
            x = up - (up @ z) * z
            if np.linalg.norm(x) < 1e-6:
                x = np.array([1.0, 0.0, 0.0]) - z[0] * z
            x = x / np.linalg.norm(x)
            out.append((GripFrame(block, f, point, np.column_stack((x, np.cross(z, x), z)),
                                  np.asarray(n, dtype=float)), on))
        return out

    def _box(self, robot: Robot, grip: GripFrame) -> fcl.CollisionObject:
        centre, rotation = tool_box_pose(robot, grip)
        return fcl.CollisionObject(fcl.Box(*robot.tool.box), fcl.Transform(rotation, centre))

    def collides(self, robot: Robot, grip: GripFrame, present=None) -> tuple[str, ...]:
        """The blocks of ``present`` (None: every other block) ``robot``'s gripper box at
        ``grip`` touches."""
        box, request = self._box(robot, grip), fcl.CollisionRequest()
        others = self.near(grip.block) if present is None else self.near(grip.block) & present
        # each block as the insertion check sees a present one (its convex pieces, exact for
        # a non-convex block; kept there), shrunk by the standoff
        return tuple(sorted(b for b in others if any(
            fcl.collide(box, piece, request, fcl.CollisionResult())
            for piece, _ in present_pieces(self.assembly.block(b), STANDOFF))))

    def in_the_way(self, block: str, robot: Robot, grip: GripFrame) -> bool:
        """Whether placing ``block`` lands on the face ``robot`` grips at ``grip`` or hits
        its gripper box."""
        on = next(o for g, o in self.faces(grip.block) if g.face == grip.face) \
            if grip.face >= 0 else frozenset()
        return block in on or bool(self.collides(robot, grip, frozenset((block,))))

    def choose(self, block: str, robot: Robot, present=None, carry: bool = False,
               hold: bool = False) -> tuple[GripFrame | None, str]:
        """``robot``'s grip of ``block`` with the blocks ``present`` (None: the finished
        assembly): on a face none of them touches, faces free in the finished assembly first
        (no later block lands on them), then the one facing the robot's base most (``hold``:
        the robot will hold the block, the one of least hold torque, :func:`hold_torque`);
        its gripper clear of them, within reach, ``carry`` (to place it) its carry wrench
        within the payload, with a URDF an inverse kinematics solution. None and why not
        when there is none."""
        near = self.near(block)
        here = near if present is None else near & frozenset(present)
        key = (block, robot.name, here, carry, hold)
        if key not in self._chosen:
            self._chosen[key] = self._choose(block, robot, here, carry, hold)
        return self._chosen[key]

    def _choose(self, block: str, robot: Robot, here: frozenset[str], carry: bool,
                hold: bool) -> tuple[GripFrame | None, str]:
        base = np.asarray(robot.base, dtype=float)
        faces = [(g, on) for g, on in self.faces(block) if not on & here]
        if not faces:
            return None, f"block {block} has no face free of contacts to grip"
        b = self.assembly.block(block)

        def rank(face):
            g, on = face
            least = hold_torque(robot, g, b, self.assembly.gravity) if hold else 0.0
            return bool(on), least, -float(g.normal @ _unit(base - g.point)), g.face

        why = []
        for g, on in sorted(faces, key=rank):
            distance = float(np.linalg.norm(g.point - base))
            if distance > robot.reach:
                why.append(f"face {g.face} {distance:.2f} m from {robot.name}'s base "
                           f"(reach {robot.reach:g} m)")
                continue
            hit = self.collides(robot, g, here)
            if hit:
                why.append(f"face {g.face}: {robot.name}'s gripper hits {', '.join(hit[:3])}")
                continue
            if carry:
                w = carry_wrench(robot, g, self.assembly.block(block), self.assembly.gravity)
                if w.utilisation > 1.0:
                    why.append(f"face {g.face}: carrying it needs {wrench_need(w, robot)}")
                    continue
            if robot.urdf and solve_ik(robot, g.point, g.rotation) is None:
                why.append(f"face {g.face}: no inverse kinematics solution")
                continue
            return g, ""
        return None, f"{robot.name} cannot grip block {block}: {'; '.join(why)}"


def _unit(v: np.ndarray) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


def validate_cell(cell: Cell, scene: Scene) -> None:
    """What a cell's fields alone cannot tell (CellError naming the robot and field): a base
    inside a block of ``scene``, a tool heavier than its robot's payload, a URDF that does
    not load (or lacks its tip link)."""
    blocks = pose_blocks(scene.blocks)
    for r in cell.robots:
        base = np.asarray(r.base, dtype=float)
        for b in blocks:
            if b.convex and np.all(b.face_normals @ base - b.face_offsets < -1e-9):
                raise CellError(f"cell: robot {r.name!r}: 'base' {list(r.base)} is inside "
                                f"block {b.id}")
        if r.tool.mass * 9.81 > r.payload_force:
            raise CellError(f"cell: robot {r.name!r}: 'payload_force' {r.payload_force:g} N "
                            f"is less than its tool's weight ({r.tool.mass * 9.81:.4g} N)")
        if r.urdf:
            load_arm(r)


__all__ = ["GripChooser", "GripFrame", "PRE_GRIP", "RobotWrench", "carry_wrench",
           "hold_torque", "robot_grip", "robot_wrench", "tool_box_pose", "validate_cell",
           "wrench_need"]
