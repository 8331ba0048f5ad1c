"""The one options object of a check: solve, contact detection, validation, hold search.

Every entry point (CLI, node parameters, options stored in a bag) builds a
:class:`CheckOptions`; the analyses read it and nothing else.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

from ..geometry.contacts import ContactOptions
from ..rbe.solver import SolveOptions
from ..scene import ValidationLimits


@dataclass(frozen=True)
class HoldSearch:
    """How an unstable check looks for the smallest set of blocks to hold (suggested_holds;
    :mod:`rbe_ros.analysis.holds`): exact by increasing size up to ``max_size`` blocks while
    at most ``max_checks`` sub-assembly checks are spent, then a greedy heuristic that
    evaluates up to ``greedy_width`` candidates per added block. Counted in checks, not
    seconds, so that a replay suggests the same holds on any machine. Each trial checks the
    whole assembly, so assemblies of more than ``max_free_blocks`` free blocks are not
    searched (the cost grows with the number of components times their size)."""

    enabled: bool = True
    max_size: int = 3
    max_checks: int = 40
    greedy_width: int = 4
    max_free_blocks: int = 60

    def __post_init__(self):
        for name in ("max_size", "max_checks", "greedy_width", "max_free_blocks"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"hold search {name} must be an integer >= 0, not {value!r}")


@dataclass(frozen=True)
class InsertionOptions:
    """Whether a report says from where its placed block can arrive (analysis/insertion.py),
    over which distance its path must be free (m; 0: until it is clear of every present
    block's bounding box), and the largest angle from straight down (along gravity) of its
    direction (degrees; 180: any direction, down preferred)."""

    enabled: bool = True
    approach_distance: float = 0.0
    approach_max_angle: float = 180.0


@dataclass(frozen=True)
class CheckOptions:
    """Everything that decides a check's result."""

    solve: SolveOptions = field(default_factory=SolveOptions)
    #: Friction threshold below mu: the cone of the deciding problem (see ``deciding``) and the
    #: bound of every interface's |V| <= mu_threshold N; None: the solve's mu.
    mu_threshold: float | None = None
    tension_tol: float = 1e-5           # tension counts above this share of the free weight
    contact: ContactOptions = field(default_factory=ContactOptions)
    full_solve: bool = False            # sequences: always solve the whole partial assembly
    holds: HoldSearch = field(default_factory=HoldSearch)   # suggested holds of unstable checks
    #: Horizontal directions of the stability margin (margin.py); 0: no margin computed.
    margin_directions: int = 0
    #: Sane ranges checked before the geometry stage (None: no validation); see validate.py.
    limits: ValidationLimits | None = field(default_factory=ValidationLimits)
    insertion: InsertionOptions = field(default_factory=InsertionOptions)
    #: Capacities of a robot's hold of a held block (N, N m; a scene hold's own win): the
    #: wrench it applies at its grip, |F| <= hold_force_max and |M| <= hold_torque_max;
    #: None: unbounded (a held block then stands like a support).
    hold_force_max: float | None = None
    hold_torque_max: float | None = None

    def __post_init__(self):
        for name in ("hold_force_max", "hold_torque_max"):
            value = getattr(self, name)
            if value is not None and not value >= 0:
                raise ValueError(f"{name} must be >= 0 or None (unbounded), not {value!r}")

    @property
    def threshold(self) -> float:
        """The friction threshold of the post-check: ``mu_threshold``, else the solve's mu."""
        return self.solve.mu if self.mu_threshold is None else self.mu_threshold

    @property
    def deciding(self) -> SolveOptions:
        """The problem whose feasibility is the verdict: the solve's, with its cone at the
        friction threshold when that is below mu. A threshold checked only on one solution
        at mu would judge an arbitrary member of a face of optimal force fields (a wall's
        course joints put at the limit where the wall needs no friction); stated as the cone,
        the step is within the threshold exactly when some admissible field is."""
        if self.threshold < self.solve.mu:
            return replace(self.solve, mu=self.threshold)
        return self.solve
