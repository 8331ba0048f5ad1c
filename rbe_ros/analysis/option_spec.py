"""The one specification of the check options.

One row per option: where it lives in :class:`CheckOptions` (its dotted path, also its key in
the JSON stored in bags), type, range or choices, help, command-line flag and ``rbe_node``
parameter; defaults are those of :class:`CheckOptions`. The CLI's arguments, the node's
parameter descriptors and range checks, the options stored in bags and live replay's node
parameters are all made from :data:`OPTIONS`, so an option added here reaches all four.

Flags and parameters carry the outer value: 0 stands for "none" where the core's value is
None or infinite (``friction_threshold`` 0: the friction coefficient; ``check_time_limit`` 0:
no limit), and a flag of a boolean that is on by default turns it off (``--no-...``).
"""
from __future__ import annotations

import json
import math
import numbers
from dataclasses import dataclass, replace
from functools import reduce

from ..rbe.cones import CONES, FRICTION_MODELS
from ..rbe.solver import OBJECTIVES
from ..scene import ValidationLimits
from .margin import DEFAULT_DIRECTIONS
from .options import CheckOptions

NONE, INFINITE = "none", "inf"


@dataclass(frozen=True)
class Option:
    """One option: where it lives in CheckOptions, its flag, node parameter and range."""

    path: str                   # attribute path in CheckOptions; the stored JSON key
    kind: type                  # float, int, bool or str
    help: str
    flag: str | None = None     # command-line flag (None: none)
    param: str | None = None    # rbe_node parameter (None: none)
    low: float | None = None    # range (numbers)
    high: float | None = None
    low_open: bool = False      # low itself excluded
    choices: tuple[str, ...] = ()
    zero: str | None = None     # NONE or INFINITE: the core value that an outer 0 stands for
    true_as: int | None = None  # a bool outside for an integer inside: true is this, false 0
    stored: bool = True         # in the options stored in bags (a replay checks with them)
    metavar: str | None = None

    @property
    def default(self):
        """The outer default (flag and parameter)."""
        return self.outer(CheckOptions())

    def outer(self, options: CheckOptions):
        """The flag and parameter value of this option in ``options``."""
        value = self.get(options)
        if self.zero is not None and (value is None or value == math.inf):
            return self.kind(0)
        if self.true_as is not None:
            return value != 0
        return value

    def inner(self, value):
        """The core value of an outer ``value``."""
        if self.zero is not None and value == 0:
            return None if self.zero == NONE else math.inf
        if self.true_as is not None:
            return self.true_as if value else 0
        return self.kind(value)

    def get(self, options: CheckOptions):
        """The core value of this option in ``options``."""
        owner = reduce(getattr, self.path.split(".")[:-1], options)
        if owner is None:                       # limits=None (not validated): the defaults
            owner = ValidationLimits()
        return getattr(owner, self.path.rsplit(".", 1)[-1])

    def set(self, options: CheckOptions, value) -> CheckOptions:
        """``options`` with this option at the core ``value``."""
        return _replaced(options, self.path.split("."), value)

    def problem(self, value) -> str | None:
        """Why an outer ``value`` is not allowed (None: allowed)."""
        if self.kind is bool:
            return None if isinstance(value, bool) else "must be true or false"
        if self.kind is str:
            if self.choices and value not in self.choices:
                return f"must be one of {', '.join(self.choices)}, not {value!r}"
            return None
        ok = (isinstance(value, numbers.Real) and not isinstance(value, bool)
              and math.isfinite(value) and (self.kind is float or float(value).is_integer())
              and (value > self.low if self.low_open else value >= self.low)
              and value <= self.high)
        if ok:
            return None
        interval = f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}]"
        return f"must be {'an integer' if self.kind is int else 'a number'} in {interval}, " \
               f"not {value!r}"


def _replaced(obj, path: list[str], value):
    if len(path) == 1:
        return replace(obj, **{path[0]: value})
    child = getattr(obj, path[0])
    if child is None:                                       # limits=None
        child = ValidationLimits()
    return replace(obj, **{path[0]: _replaced(child, path[1:], value)})


_LENGTH = "relative to the smaller block's size (the cube root of its volume)"

#: Every check option. Those without a flag or parameter are stored in bags only (fixed in
#: the CLI and the node: a bag recorded with others is replayed offline).
OPTIONS: tuple[Option, ...] = (
    Option("solve.mu", float, "Coulomb friction coefficient mu of every interface",
           "--mu", "friction_coefficient", 0.0, 10.0, low_open=True),
    Option("mu_threshold", float, "friction threshold: below mu, the cone of the check "
           "(|V| <= threshold * N); 0: the friction coefficient", "--mu-threshold",
           "friction_threshold", 0.0, 10.0, zero=NONE),
    Option("solve.objective", str, "objective of the force solve: qp (smooth, unique forces) "
           "or lp", "--objective", "objective", choices=OBJECTIVES),
    Option("solve.friction", str, "net (friction-net: decides stability) or plus (friction+: "
           "always feasible, shows where tension is needed)", "--friction", "friction_model",
           choices=FRICTION_MODELS),
    Option("solve.cone", str, "friction cone: exact second-order cone or a linearised pyramid",
           "--cone", "friction_cone", choices=CONES),
    Option("tension_tol", float, "a vertex tension counts above this share of the free "
           "blocks' weight", "--tension-tol", "tension_tolerance", 0.0, 1.0),
    Option("solve.time_limit", float, "time limit in s of each check (of each step of a "
           "sequence), geometry included; over it the report is SOLVER_FAILED naming the "
           "stage; plan: of the whole search, then the best partial plan; 0: none",
           "--time-limit", "check_time_limit", 0.0, 3600.0, zero=INFINITE,
           stored=False, metavar="S"),
    Option("margin_directions", bool, "reports carry margin_g: the smallest horizontal "
           "acceleration (share of g) that topples or slides the checked assembly, over "
           f"{DEFAULT_DIRECTIONS} directions, and margin_direction (about one solve per "
           "direction)", "--margin", "compute_margin", true_as=DEFAULT_DIRECTIONS),
    Option("full_solve", bool, "sequences: solve every step's whole assembly instead of local "
           "models (a report's model field says which answered)", "--full-solve",
           "full_solve"),
    Option("limits.max_blocks", int, "largest number of blocks of a scene; a larger one is "
           "refused (INVALID_INPUT); the other sane ranges: README", "--max-blocks",
           "max_blocks", 1, 1_000_000, stored=False, metavar="N"),
    Option("contact.distance_tol", float, "contact detection: largest gap or overlap between "
           f"two face planes in contact, {_LENGTH}; noisy meshes need more", "--distance-tol",
           "contact_distance_tolerance", 0.0, 1.0, metavar="R"),
    Option("contact.angle_tol_deg", float, "contact detection: largest deviation of two faces' "
           "normals from opposite, in degrees", "--angle-tol", "contact_angle_tolerance_deg",
           0.0, 90.0, metavar="DEG"),
    Option("contact.min_area", float, "contact detection: smallest interface area, relative "
           "to the size squared", "--min-area", "contact_min_area", 0.0, 1.0, metavar="R"),
    Option("contact.min_width", float, "contact detection: thinner interface polygons are "
           f"edge contacts and are left out, {_LENGTH}; 0 keeps all", "--min-width",
           "contact_min_width", 0.0, 1.0, metavar="R"),
    Option("contact.vertex_tol", float, "contact detection: interface vertices closer than "
           f"this to their neighbours' chord are left out, {_LENGTH}; 0 keeps all",
           "--vertex-tol", "contact_vertex_tolerance", 0.0, 1.0, metavar="R"),
    Option("contact.pose_uncertainty_m", float, "as-built poses: every block's position is "
           "known to within this many m (about 3 sigma); contacts and the interpenetration "
           "limit follow from it (0 with pose_uncertainty_deg 0: the scene's declared one, "
           "else design geometry)", "--pose-uncertainty-m", "pose_uncertainty_m", 0.0, 1.0,
           metavar="M"),
    Option("contact.pose_uncertainty_deg", float, "as-built poses: every block's orientation "
           "is known to within this many degrees (about 3 sigma)", "--pose-uncertainty-deg",
           "pose_uncertainty_deg", 0.0, 90.0, metavar="DEG"),
    Option("holds.enabled", bool, "an unstable report names the smallest set of blocks to "
           "hold (suggested_holds)", "--no-suggest-holds", "suggest_holds"),
    Option("holds.max_size", int, "suggested holds: exact search up to this many blocks, then "
           "a greedy heuristic", "--hold-max-size", "hold_search_max_size", 0, 1000,
           metavar="N"),
    Option("holds.max_checks", int, "suggested holds: sub-assembly checks the exact search may "
           "spend", "--hold-max-checks", "hold_search_max_checks", 0, 1_000_000, metavar="N"),
    Option("insertion.enabled", bool, "reports say whether the placed block can reach its "
           "pose (insertable) and along which direction (insertion_direction)",
           "--no-insertion", "insertion_check"),
    Option("insertion.approach_distance", float, "insertion: the placed block's path must be "
           "free over this many m; 0: until it is clear of every present block's bounding "
           "box", "--approach-distance", "approach_distance", 0.0, 100.0, metavar="M"),
    Option("insertion.approach_max_angle", float, "insertion: the largest angle in degrees "
           "from straight down (along gravity) a block may arrive from (a top-down gripper: "
           "small); 180: any direction, down preferred", "--approach-max-angle",
           "approach_max_angle", 0.0, 180.0, metavar="DEG"),
    Option("hold_force_max", float, "largest force in N a robot's hold may apply to a held "
           "block (at its grip); a step that stands only with more is HOLD_EXCEEDED; a scene "
           "hold's \"max_force\" wins; 0: unbounded", "--hold-force-max", "hold_force_max",
           0.0, 1e9, zero=NONE, metavar="N"),
    Option("hold_torque_max", float, "largest torque in N m a robot's hold may apply to a "
           "held block (about its grip); a scene hold's \"max_torque\" wins (0 there: a pin "
           "grip); 0: unbounded", "--hold-torque-max", "hold_torque_max", 0.0, 1e9,
           zero=NONE, metavar="NM"),
    # fixed in the CLI and the node; stored so that a replay uses what a recording used
    Option("solve.weights.compression", float, "objective weight of compression"),
    Option("solve.weights.tension", float, "objective weight of tension (friction+ penalty)"),
    Option("solve.weights.friction", float, "objective weight of friction"),
    Option("solve.allow_tension", bool, "friction+ may use tension"),
    Option("holds.greedy_width", int, "suggested holds: candidates per added block of the "
           "greedy heuristic"),
    Option("holds.max_free_blocks", int, "suggested holds: larger assemblies are not searched"),
)

BY_PATH = {o.path: o for o in OPTIONS}
BY_PARAM = {o.param: o for o in OPTIONS if o.param}


def from_outer(values: dict[Option, object], base: CheckOptions = CheckOptions()
               ) -> CheckOptions:
    """``base`` with the options of ``values`` (outer values, checked: ValueError naming the
    option's flag or parameter)."""
    options = base
    for option, value in values.items():
        problem = option.problem(value)
        if problem is not None:
            raise ValueError(f"{option.flag or option.param or option.path} {problem}")
        options = option.set(options, option.inner(value))
    return options


def to_json(options: CheckOptions) -> str:
    """The stored options as JSON, nested by path (a bag's metadata)."""
    data: dict = {}
    for option in OPTIONS:
        if option.stored:
            *parents, name = option.path.split(".")
            reduce(lambda d, k: d.setdefault(k, {}), parents, data)[name] = option.get(options)
    return json.dumps(data, sort_keys=True)


def from_json(text: str, base: CheckOptions = CheckOptions()) -> CheckOptions:
    """``base`` with the options stored in ``text`` (:func:`to_json`; keys missing: kept)."""
    data = json.loads(text)
    options = base
    for option in OPTIONS:
        *parents, name = option.path.split(".")
        owner = reduce(lambda d, k: d.get(k, {}) if isinstance(d, dict) else {}, parents, data)
        if option.stored and isinstance(owner, dict) and name in owner:
            options = option.set(options, owner[name])
    return options


def node_parameters(options: CheckOptions) -> dict[str, object]:
    """rbe_node parameters for ``options`` (ValueError naming what the node cannot be set to:
    options without a parameter that differ from the default, values a parameter cannot
    express)."""
    bad = [o.path for o in OPTIONS if o.get(options) != (
        o.get(CheckOptions()) if o.param is None else o.inner(o.outer(options)))]
    if bad:
        raise ValueError(f"rbe_node has no parameters for {', '.join(bad)}: replay offline")
    return {o.param: o.outer(options) for o in OPTIONS if o.param}
