"""Results of an RBE check: per-interface forces and resultants, and the verdict."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np


class Status(IntEnum):
    """Verdict codes, equal to the constants of rbe_msgs/StabilityReport."""

    STABLE = 0
    TENSION_REQUIRED = 1
    FRICTION_EXCEEDED = 2
    INFEASIBLE = 3
    SOLVER_FAILED = 4
    INVALID_INPUT = 5
    HOLD_EXCEEDED = 6       # stands only with a hold wrench beyond the robot's capacity


@dataclass(frozen=True)
class InterfaceResult:
    """Forces block_a exerts on block_b over one contact polygon (SI units, assembly frame)."""

    block_a: str
    block_b: str
    normal: np.ndarray              # (3,) unit, from a into b
    polygon: np.ndarray             # (k, 3) vertices where the forces act
    normal_forces: np.ndarray       # (k,) signed: + compression, - tension
    tangential_forces: np.ndarray   # (k, 3)
    resultant: np.ndarray           # (3,) total force
    normal_resultant: float         # N
    shear: np.ndarray               # (3,) V
    centre_of_pressure: np.ndarray  # (3,)
    torque: float                   # about the normal through the centre of pressure
    kern: np.ndarray                # (m, 3)
    friction_ratio: float           # |V| / N
    tension: bool
    friction_exceeded: bool


@dataclass(frozen=True)
class NearContact:
    """A face pair just beyond the contact tolerance: not an interface, but a contact if the
    poses were a little off (see rbe_ros.geometry.uncertainty)."""

    block_a: str
    block_b: str
    gap: float              # m, between the faces (negative: they overlap)
    overlap_area: float     # m^2, of the two faces projected on their mid-plane


@dataclass(frozen=True)
class HoldWrench:
    """What a robot holding ``block`` must apply: ``force`` (N) at ``grip_point`` (world) and
    ``torque`` (N m) about it, the smallest that lets the step stand (see
    :data:`rbe_ros.rbe.solver.HOLD_WEIGHT`). ``utilisation``: the larger of |F| / max_force
    and |M| / max_torque over the bounded ones (0 when both are unbounded; above 1 in a
    HOLD_EXCEEDED report: the wrench needed)."""

    block: str
    force: np.ndarray           # (3,)
    torque: np.ndarray          # (3,)
    grip_point: np.ndarray      # (3,)
    utilisation: float = 0.0


#: margin_g of a report whose check computed no margin (a margin is never negative).
NOT_COMPUTED = -1.0


@dataclass(frozen=True)
class Report:
    """Verdict of one check of an assembly or of one step of a sequence; made once, never
    changed (:func:`dataclasses.replace` makes a changed copy)."""

    status: Status
    message: str
    max_tension: float = 0.0
    worst_friction_ratio: float = 0.0
    solve_time: float = 0.0   # s: validation, contacts, solves and hold search of the check
    num_blocks: int = 0
    interfaces: tuple[InterfaceResult, ...] = ()
    unstable_blocks: tuple[str, ...] = ()
    step_index: int = -1
    block_placed: str = ""
    model: str = "full"   # which model answered: "full", "local N" or "relaxed N"
    held_blocks: tuple[str, ...] = ()       # free blocks held as supports
    suggested_holds: tuple[str, ...] = ()   # smallest set to hold, if unstable
    dropped_states: int = 0   # node: states on ~/assembly dropped unchecked so far (overload)
    near_contacts: tuple[NearContact, ...] = ()
    verdict_sensitive: bool = False     # the verdict depends on the contact tolerance
    #: Smallest horizontal acceleration (share of g) that topples or slides the checked
    #: assembly over the margin's directions, 0 when it does not stand; NOT_COMPUTED (-1)
    #: when no margin was asked for.
    margin_g: float = NOT_COMPUTED
    margin_direction: np.ndarray = field(default_factory=lambda: np.zeros(3))  # body force, unit
    #: Whether the placed block can reach its pose past the present blocks (true when not
    #: checked: no block placed, the check off, or no verdict), along insertion_direction
    #: (unit, its motion into the pose; zeros when it cannot or nothing was checked).
    insertable: bool = True
    insertion_direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    hold_wrenches: tuple[HoldWrench, ...] = ()   # per held block: the robot's wrench

    def __post_init__(self):
        for name in ("interfaces", "unstable_blocks", "held_blocks", "suggested_holds",
                     "near_contacts", "hold_wrenches"):
            object.__setattr__(self, name, tuple(getattr(self, name)))

    @property
    def stable(self) -> bool:
        """Whether the assembly (or step) stands: the status says so."""
        return self.status == Status.STABLE
