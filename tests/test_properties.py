"""Property-based tests of the core (hypothesis): random stacks and walls.

* a stack's verdict is the closed-form one of tests/oracles/stacks.py (the overhang rule and
  tan(tilt) against mu), for random mu, cones, objectives and friction models, and each
  verdict is backed by its explanation: INFEASIBLE names exactly the boxes above a gap,
  TENSION_REQUIRED shows tension at every interface whose load line is outside, and
  FRICTION_EXCEEDED flags the sliding interfaces at |V|/N = tan(tilt); a STABLE stack has
  the closed-form normal resultants and centres of pressure;
* every answer with forces is in equilibrium to 1e-6 of the weight (recomputed here from the
  reported vertex forces alone, masses from tests/oracles/mass.py), and a STABLE one has
  every vertex inside its friction cone and no tension;
* verdicts and interface forces do not change under a rigid motion of the whole scene
  (positions, orientations and gravity) nor under renaming and reordering the blocks;
* a mirror-symmetric scene gets mirror-symmetric QP forces.

Scenes close to a verdict boundary (a load line within 1% of an interface edge, a barely
touching pair of blocks) are skipped with ``assume``: there the verdict may legitimately
flip with rounding; where tan(tilt) is within 2 % of a friction limit, or the direction
of sliding against a pyramid's facets decides, the oracle allows either verdict. Profiles
(tests/conftest.py): ``ci`` runs 100 examples per test, 500 scenes in all;
``HYPOTHESIS_PROFILE=long`` (``make test-long``) 10,000.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest
import shapely
from hypothesis import assume, event, example, given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from rbe_ros.analysis.options import CheckOptions, HoldSearch
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.rbe.cones import CONES, FRICTION_MODELS, cone_capacity
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import SolveOptions
from rbe_ros.scene import box_block, make_scene

from helpers import cone_excess, equilibrium_residual
from oracles import stacks as stack_oracle

MU = 0.6
G = 9.81
GROUND = 20.0          # the support slab's width (m)
#: The walls' and the symmetry tests' check: their properties are of the verdict and the
#: forces, which the hold search does not change (it only names blocks to hold, which
#: tests/test_holds.py checks against brute force); on a tilted wall that slides it was
#: nine tenths of the check. The stacks' test keeps it on.
VERDICT = CheckOptions(holds=HoldSearch(enabled=False))


@dataclass(frozen=True)
class Box:
    id: str
    size: tuple[float, float, float]
    centre: tuple[float, float, float]
    yaw: float = 0.0
    density: float = 2000.0
    support: bool = False

    def block(self):
        q = Rotation.from_euler("z", self.yaw).as_quat()
        return box_block(self.id, self.size, self.centre, q, density=self.density,
                         support=self.support)

    def footprint(self) -> shapely.Polygon:
        sx, sy = self.size[0] / 2, self.size[1] / 2
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        pts = [(self.centre[0] + c * x - s * y, self.centre[1] + s * x + c * y)
               for x, y in ((-sx, -sy), (sx, -sy), (sx, sy), (-sx, sy))]
        return shapely.Polygon(pts)

    @property
    def mass(self) -> float:
        return self.density * self.size[0] * self.size[1] * self.size[2]


@dataclass(frozen=True)
class Spec:
    boxes: tuple[Box, ...]
    gravity: tuple[float, float, float] = (0.0, 0.0, -G)

    def scene(self):
        return make_scene("random", [b.block() for b in self.boxes], self.gravity)

    def oracle_boxes(self) -> list[stack_oracle.StackBox]:
        return [stack_oracle.StackBox(b.id, b.footprint(), b.centre, b.centre[2] - b.size[2] / 2,
                                      b.mass) for b in self.boxes]


def ground(top: float = 0.0) -> Box:
    return Box("ground", (GROUND, GROUND, 0.2), (0.0, 0.0, top - 0.1), support=True)


def gravity_of(tilt_deg: float, azimuth: float) -> tuple[float, float, float]:
    t = math.radians(tilt_deg)
    return (G * math.sin(t) * math.cos(azimuth), G * math.sin(t) * math.sin(azimuth),
            -G * math.cos(t))


size = st.floats(0.2, 1.2)
tilts = st.one_of(st.just(0.0), st.floats(0.0, 40.0))


@st.composite
def stacks(draw, tilt: bool = True) -> Spec:
    """1-4 boxes of random size and yaw, each on the one below with a random offset, under a
    gravity tilted by up to 40 deg; far from every verdict boundary."""
    n = draw(st.integers(1, 4))
    boxes = [ground()]
    z = 0.0
    for k in range(n):
        sx, sy, sz = draw(size), draw(size), draw(size)
        below = boxes[-1]
        if below.support:
            cx, cy = draw(st.floats(-1.0, 1.0)), draw(st.floats(-1.0, 1.0))
        else:
            reach = 0.5 * (max(below.size[:2]) + max(sx, sy))
            cx = below.centre[0] + draw(st.floats(-0.8, 0.8)) * reach
            cy = below.centre[1] + draw(st.floats(-0.8, 0.8)) * reach
        boxes.append(Box(f"b{k}", (sx, sy, sz), (cx, cy, z + sz / 2),
                         draw(st.floats(-math.pi, math.pi)), draw(st.floats(1000.0, 3000.0))))
        z += sz
    g = gravity_of(draw(tilts) if tilt else 0.0, draw(st.floats(0.0, 2 * math.pi)))
    spec = Spec(tuple(boxes), g)
    assume(_clear_of_boundaries(spec))
    return spec


def _clear_of_boundaries(spec: Spec) -> bool:
    """No contact or load-line boundary within reach of rounding: contacts clearly there or
    clearly not, each load line clearly inside or outside its contact polygon."""
    boxes = spec.boxes
    for k, it in enumerate(stack_oracle.interfaces(spec.oracle_boxes(), spec.gravity), start=1):
        lower, upper = boxes[k - 1].footprint(), boxes[k].footprint()
        scale = min(min(boxes[k].size[:2]), min(boxes[k - 1].size[:2]))
        if it.polygon.area == 0.0:
            if lower.distance(upper) < 0.01 * scale:
                return False
            continue
        if it.polygon.area < 0.02 * min(lower.area, upper.area) or abs(it.margin) < 0.01 * scale:
            return False
    return True


@st.composite
def walls(draw, tilt: bool = False) -> Spec:
    """1-3 courses, each cut into 1-4 bricks of random lengths (courses cover the whole
    span, so every brick is fully supported), on a support; optionally tilted gravity."""
    courses = draw(st.integers(1, 3))
    span, thick = draw(st.floats(0.6, 2.0)), draw(st.floats(0.15, 0.4))
    height = draw(st.floats(0.1, 0.4))
    x0 = draw(st.floats(-1.0, 1.0))
    boxes = [ground()]
    for c in range(courses):
        weights = draw(st.lists(st.floats(1.0, 3.0), min_size=1, max_size=4))
        cuts = x0 + span * np.concatenate(([0.0], np.cumsum(weights) / sum(weights)))
        cuts[-1] = x0 + span
        for b, (lo, hi) in enumerate(zip(cuts[:-1], cuts[1:])):
            boxes.append(Box(f"c{c}_{b}", (hi - lo, thick, height),
                             ((lo + hi) / 2, 0.0, (c + 0.5) * height)))
    g = gravity_of(draw(tilts) if tilt else 0.0, draw(st.floats(0.0, 2 * math.pi)))
    return Spec(tuple(boxes), g)


def free_weight(scene) -> float:
    from rbe_ros.geometry.block import pose_block
    return sum(pose_block(b).mass for b in scene.blocks if not b.support) * G


def assert_admissible(scene, report, mu: float = MU, cone: str = "soc") -> None:
    """Equilibrium from the reported forces; a STABLE answer within the cones, no tension."""
    if report.status not in (Status.STABLE, Status.TENSION_REQUIRED, Status.FRICTION_EXCEEDED):
        assert report.status == Status.INFEASIBLE, report.message
        return
    assert equilibrium_residual(scene, report) < 1e-6, report.message
    if report.status == Status.STABLE:
        assert cone_excess(report, mu, cone) <= 1e-6 * free_weight(scene), report.message
        assert all(r.friction_ratio <= mu + 1e-6 for r in report.interfaces)


options = st.builds(lambda mu, cone, objective, friction: SolveOptions(
    mu=mu, cone=cone, objective=objective, friction=friction),
    st.floats(0.2, 1.2), st.sampled_from(CONES), st.sampled_from(("qp", "lp")),
    st.sampled_from(FRICTION_MODELS))


#: Two boxes under a gravity tilted to tan = 0.55, 8 % short of mu = 0.6 (exact cone): STABLE;
#: a cone built a tenth too narrow makes it slide.
NEAR_MU = Spec((ground(), Box("b0", (0.6, 0.5, 0.4), (0.1, -0.2, 0.2), 0.3),
                Box("b1", (0.5, 0.5, 0.3), (0.15, -0.1, 0.55), -0.2)),
               gravity_of(math.degrees(math.atan(0.55)), 0.7))


@given(stacks(), options)
@example(NEAR_MU, SolveOptions(mu=0.6))
@example(NEAR_MU, SolveOptions(mu=0.6, objective="lp", friction="plus"))
def test_stack_verdict_is_the_closed_form_one_and_explained(spec, solve):
    scene = spec.scene()
    report = check_scene(scene, CheckOptions(solve))
    expected = stack_oracle.verdicts(spec.oracle_boxes(), spec.gravity, solve.mu, solve.cone,
                                     solve.friction)
    event(report.status.name)
    assert report.status.name in expected, (expected, report.message)
    assert_admissible(scene, report, solve.mu, solve.cone)
    its = stack_oracle.interfaces(spec.oracle_boxes(), spec.gravity)
    g = np.array(spec.gravity)
    tan = math.hypot(g[0], g[1]) / -g[2]
    by_pair = {(r.block_a, r.block_b): r for r in report.interfaces}
    if report.status == Status.INFEASIBLE:
        # explained: exactly the boxes above the lowest gap float
        gap = next(k for k, it in enumerate(its) if it.polygon.area == 0)
        assert report.unstable_blocks == tuple(sorted(b.id for b in spec.boxes[gap + 1:]))
        assert "not connected to a support" in report.message
    elif report.status == Status.TENSION_REQUIRED:
        assert report.max_tension > 1e-5 * free_weight(scene)
        if any(it.margin < 0 for it in its):
            # explained: tension at every interface whose load line is outside, the box on
            # it named as the one that would tip
            for it in its:
                if it.margin < 0:
                    assert by_pair[(it.below, it.above)].tension, (it.below, it.above)
                    assert it.above in report.unstable_blocks
        else:
            # friction+ only: glue raises fn+ so that tan(tilt) beyond the cone's smallest
            # capacity (mu, or mu h of an inscribed pyramid) can be carried
            assert solve.friction == "plus" and tan > solve.mu * cone_capacity(solve.cone)
            assert report.worst_friction_ratio == pytest.approx(tan, rel=1e-5)
    elif report.status == Status.FRICTION_EXCEEDED:
        # explained: every interface needs tan(tilt), so the boxes slide together on the
        # lowest one (the least constraint's motion: rbe/prestress.py), all named
        assert by_pair[(its[0].below, its[0].above)].friction_exceeded
        assert report.unstable_blocks == tuple(sorted(b.id for b in spec.boxes
                                                      if not b.support))
        assert report.worst_friction_ratio == pytest.approx(tan, rel=1e-5, abs=1e-7)
    elif report.status == Status.STABLE:
        # the statically determinate chain: closed-form resultants and centres of pressure
        for it in its:
            r = by_pair[(it.below, it.above)]
            assert r.normal_resultant == pytest.approx(it.normal_force, rel=1e-6)
            assert np.allclose(r.centre_of_pressure[:2], it.point, atol=1e-6)
            assert r.friction_ratio == pytest.approx(tan, rel=1e-5, abs=1e-7)


@given(walls(tilt=True))
def test_walls_are_in_equilibrium_and_within_the_cones(spec):
    scene = spec.scene()
    report = check_scene(scene, VERDICT)
    assert_admissible(scene, report)
    if math.hypot(*spec.gravity[:2]) == 0.0:
        assert report.status == Status.STABLE, report.message


def signature(report, rename=lambda i: i) -> tuple:
    """Status, largest tension and the interfaces' normal resultants keyed by block pair.

    Not the unstable blocks: they come from the interfaces whose vertex tension exceeds
    tension_tol (1e-5 of the weight), and the friction+ QP spreads small amounts of tension
    over interfaces that need none (1e6 fn-^2 costs next to nothing for tiny fn-), so an
    interface can sit at that threshold and flip with rounding (found by the long run)."""
    forces = sorted((tuple(sorted((rename(r.block_a), rename(r.block_b)))), r.normal_resultant)
                    for r in report.interfaces)
    return report.status, report.max_tension, forces


def assert_same(sig_a, sig_b, weight: float) -> None:
    """Same status; forces the same to 1e-4 of the weight (or of the tension when larger):
    the solver's accuracy, as AlmostSolved or a retried solve may give it (long run)."""
    assert sig_a[0] == sig_b[0], (sig_a[0], sig_b[0])
    assert abs(sig_a[1] - sig_b[1]) <= 1e-4 * max(weight, sig_a[1]), (sig_a[1], sig_b[1])
    assert [k for k, _ in sig_a[2]] == [k for k, _ in sig_b[2]]
    for (_, n_a), (_, n_b) in zip(sig_a[2], sig_b[2]):
        assert abs(n_a - n_b) <= 1e-4 * max(weight, abs(n_a)), (n_a, n_b)


def quaternions():
    return st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(
        lambda q: np.linalg.norm(q) > 0.1).map(lambda q: np.array(q) / np.linalg.norm(q))


@given(st.one_of(stacks(), walls()), quaternions(),
       st.tuples(*[st.floats(-50.0, 50.0)] * 3))
def test_verdict_invariant_under_rigid_motion(spec, quat, shift):
    scene = spec.scene()
    rot = Rotation.from_quat(quat)
    moved = [replace(b, position=rot.apply(b.position) + shift,
                     orientation=(rot * Rotation.from_quat(b.orientation)).as_quat())
             for b in scene.blocks]
    other = make_scene("moved", moved, rot.apply(scene.gravity))
    assert_same(signature(check_scene(scene, VERDICT)), signature(check_scene(other, VERDICT)),
                free_weight(scene))


@given(st.one_of(stacks(), walls()), st.data())
def test_verdict_invariant_under_renaming_and_reordering(spec, data):
    scene = spec.scene()
    order = data.draw(st.permutations(range(len(scene.blocks))))
    names = data.draw(st.lists(st.text("abcxyz_", min_size=1, max_size=5),
                               min_size=len(scene.blocks), max_size=len(scene.blocks)))
    new = {b.id: f"{names[k]}{k}" for k, b in enumerate(scene.blocks)}
    other = make_scene("renamed", [replace(scene.blocks[k], id=new[scene.blocks[k].id])
                                   for k in order], scene.gravity)
    assert_same(signature(check_scene(scene, VERDICT), new.get),
                signature(check_scene(other, VERDICT)), free_weight(scene))


@st.composite
def mirrored(draw) -> tuple[Spec, dict]:
    """A scene symmetric about the plane x = 0: random piers on the right (a stack of 1-3
    boxes), their mirror images on the left (yaw negated), a lintel across both, and 0-2
    centred boxes on it (shifted along y only). Returns the spec and the id mirror map."""
    boxes = [ground()]
    mirror = {"ground": "ground"}
    d = draw(st.floats(0.4, 1.5))
    z = 0.0
    widest = 0.0
    for k in range(draw(st.integers(1, 3))):
        sx, sy, sz = draw(st.floats(0.2, 0.6)), draw(st.floats(0.3, 0.8)), draw(size)
        yaw = draw(st.floats(-0.3, 0.3))
        cx = d + draw(st.floats(-0.05, 0.05))
        right = Box(f"R{k}", (sx, sy, sz), (cx, draw(st.floats(-0.05, 0.05)), z + sz / 2), yaw)
        left = Box(f"L{k}", right.size, (-cx, right.centre[1], right.centre[2]), -yaw)
        assume(left.footprint().distance(right.footprint()) > 0.05)
        boxes += [right, left]
        mirror.update({right.id: left.id, left.id: right.id})
        widest = max(widest, cx + 0.5 * max(sx, sy))
        z += sz
    lintel = Box("lintel", (2 * widest + draw(st.floats(0.0, 0.4)), draw(st.floats(0.3, 1.0)),
                            draw(st.floats(0.1, 0.4))), (0.0, 0.0, 0.0))
    lintel = replace(lintel, centre=(0.0, 0.0, z + lintel.size[2] / 2))
    boxes.append(lintel)
    mirror["lintel"] = "lintel"
    z += lintel.size[2]
    for k in range(draw(st.integers(0, 2))):
        sx, sy, sz = draw(size), draw(st.floats(0.2, 0.8)), draw(size)
        boxes.append(Box(f"C{k}", (sx, sy, sz), (0.0, draw(st.floats(-0.2, 0.2)), z + sz / 2)))
        mirror[f"C{k}"] = f"C{k}"
        z += sz
    return Spec(tuple(boxes)), mirror


@given(mirrored())
def test_mirror_symmetric_scene_gets_mirror_symmetric_qp_forces(case):
    spec, mirror = case
    scene = spec.scene()
    report = check_scene(scene, VERDICT)
    assume(report.interfaces)               # INFEASIBLE (a floating part) has no forces
    tol = 1e-5 * free_weight(scene)
    by_pair = {frozenset((r.block_a, r.block_b)): r for r in report.interfaces}
    assert len(by_pair) == len(report.interfaces)
    flip = np.array([-1.0, 1.0, 1.0])
    for key, r in by_pair.items():
        image = by_pair[frozenset(mirror[i] for i in key)]
        for p, fn, ft in zip(r.polygon, r.normal_forces, r.tangential_forces):
            k = int(np.argmin(np.linalg.norm(image.polygon - flip * p, axis=1)))
            assert np.linalg.norm(image.polygon[k] - flip * p) < 1e-9
            assert abs(image.normal_forces[k] - fn) <= tol, (key, fn, image.normal_forces[k])
            # the tangential force mirrors; the normal of an interface between a mirrored
            # pair is itself mirrored, so the image's (a, b) order may flip the sign of both
            same_side = np.allclose(image.normal, flip * r.normal, atol=1e-9)
            expected = flip * ft if same_side else -flip * ft
            assert np.linalg.norm(image.tangential_forces[k] - expected) <= tol, key
