"""The solver's problem assembly and attempts, and the vectorised interface resultants against
a plain per-interface computation."""
from __future__ import annotations

import math
from dataclasses import replace

import clarabel
import numpy as np
import pytest
import scipy.sparse as sp

from rbe_ros import generators as gen
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.geometry.polygon import cross
from rbe_ros.rbe import solver as solver_module
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.resultants import NEGLIGIBLE, interface_results
from rbe_ros.rbe.solver import SolveOptions, _Csc, solve

from helpers import stacked_boxes


def model_of(scene):
    a = Assembly.from_scene(scene)
    return build_model(a.blocks, a.interfaces, a.gravity)


def reference_results(model, solution, mu_threshold, tension_tol, mu):
    """The resultants interface by interface (the loop interface_results replaced)."""
    fn_pos, fn_neg, fu, fv = solution.forces
    fn = fn_pos - fn_neg
    tangential = fu[:, None] * model.u + fv[:, None] * model.v
    out, start = [], 0
    for it in model.interfaces:
        k = slice(start, start + len(it.points))
        start = k.stop
        pts, n = it.points, it.frame.n
        big_n = float(fn[k].sum())
        shear = tangential[k].sum(axis=0)
        shear_norm = float(np.linalg.norm(shear))
        cop = ((fn[k, None] * pts).sum(axis=0) / big_n if abs(big_n) > 1e-12 * model.force_scale
               else it.frame.origin)
        torque = float(cross(pts - cop, fn[k, None] * n + tangential[k]).sum(axis=0) @ n)
        if big_n > NEGLIGIBLE * model.force_scale:
            ratio = shear_norm / big_n
        else:
            ratio = math.inf if shear_norm > NEGLIGIBLE * model.force_scale else 0.0
        slides = shear_norm > mu * big_n + 1e-9 * model.force_scale
        out.append(dict(normal_resultant=big_n, shear=shear, centre_of_pressure=cop, torque=torque,
                        friction_ratio=ratio,
                        tension=bool(fn_neg[k].max(initial=0.0) > tension_tol * model.force_scale),
                        friction_exceeded=bool(ratio > mu_threshold * (1 + 1e-6) or slides),
                        normal_forces=fn[k], tangential_forces=tangential[k], polygon=pts))
    return out


CASES = [
    ("dome", gen.dome(8, 5), SolveOptions()),
    ("stack, friction+ with tension", stacked_boxes(0.8), SolveOptions(friction="plus")),
    ("arch, LP (interfaces without force)", gen.semicircular_arch(), SolveOptions(objective="lp")),
    ("wall, low friction+", gen.running_bond_wall(3, 4), SolveOptions(mu=0.2, friction="plus")),
]


@pytest.mark.parametrize("name, scene, options", CASES, ids=[c[0] for c in CASES])
def test_interface_results_match_the_per_interface_computation(name, scene, options):
    model = model_of(scene)
    solution = solve(model, options)
    assert solution.solved
    w, length = model.force_scale, model.length_scale
    for threshold, tension_tol in ((options.mu, 1e-5), (0.1, 1e-9)):
        results = interface_results(model, solution, mu_threshold=threshold,
                                    tension_tol=tension_tol, mu=options.mu)
        expected = reference_results(model, solution, threshold, tension_tol, options.mu)
        assert len(results) == len(expected) == len(model.interfaces)
        for r, e, it in zip(results, expected, model.interfaces):
            assert (r.block_a, r.block_b) == (model.blocks[it.a].id, model.blocks[it.b].id)
            assert np.array_equal(r.normal, it.frame.n) and r.kern is it.kern
            for key in ("polygon", "normal_forces", "tangential_forces"):
                assert np.array_equal(getattr(r, key), e[key])
            assert abs(r.normal_resultant - e["normal_resultant"]) <= 1e-12 * w
            assert np.allclose(r.shear, e["shear"], rtol=0, atol=1e-12 * w)
            assert np.allclose(r.resultant, e["normal_resultant"] * it.frame.n + e["shear"],
                               rtol=0, atol=1e-12 * w)
            assert np.allclose(r.centre_of_pressure, e["centre_of_pressure"], rtol=0,
                               atol=1e-12 * length)
            assert abs(r.torque - e["torque"]) <= 1e-12 * w * length
            assert r.friction_ratio == pytest.approx(e["friction_ratio"], rel=1e-12, abs=1e-15)
            assert (r.tension, r.friction_exceeded) == (e["tension"], e["friction_exceeded"])
            assert type(r.normal_resultant) is float and type(r.tension) is bool


@pytest.mark.parametrize("mu", [0.6, math.inf])
def test_interface_results_match_on_every_branch(mu):
    """Arbitrary forces (no equilibrium needed): interfaces without any force, with shear but
    no normal force, in net tension, with tension below and above the limit."""
    model = model_of(gen.running_bond_wall(3, 4))
    rng = np.random.default_rng(7)
    forces = rng.normal(size=(4, model.num_vertices)) * model.force_scale * 0.01
    forces[:2] = np.abs(forces[:2])
    kinds = rng.integers(0, 4, size=len(model.interfaces))[model.vertex_interface]
    forces[:, kinds == 0] = 0.0                    # nothing at all
    forces[:2, kinds == 1] = 0.0                   # shear only
    forces[0, kinds == 2] = 0.0                    # net tension
    solution = replace(solve(model), forces=forces)
    results = interface_results(model, solution, mu_threshold=0.5, tension_tol=1e-3, mu=mu)
    expected = reference_results(model, solution, 0.5, 1e-3, mu)
    flags = {"no force": 0, "inf": 0, "tension": 0, "exceeded": 0}
    for r, e in zip(results, expected):
        for key in ("normal_resultant", "torque", "friction_ratio"):
            assert getattr(r, key) == pytest.approx(
                e[key], rel=1e-12, abs=1e-12 * model.force_scale * model.length_scale)
        assert np.allclose(r.centre_of_pressure, e["centre_of_pressure"], rtol=0, atol=1e-12)
        assert (r.tension, r.friction_exceeded) == (e["tension"], e["friction_exceeded"])
        flags["no force"] += r.normal_resultant == 0.0
        flags["inf"] += r.friction_ratio == math.inf
        flags["tension"] += r.tension
        flags["exceeded"] += r.friction_exceeded
    assert all(flags.values()), flags


def test_interface_results_own_their_arrays():
    """No result aliases the model, the solution or another result: mutating one changes
    nothing else."""
    model = model_of(stacked_boxes(0.3))
    solution = solve(model)
    results = interface_results(model, solution, mu_threshold=0.6, tension_tol=1e-5)
    before = [r.normal_forces.copy() for r in results]
    points, normal, forces = model.points.copy(), model.normal.copy(), solution.forces.copy()
    for key in ("normal", "polygon", "normal_forces", "tangential_forces", "resultant", "shear",
                "centre_of_pressure"):
        getattr(results[0], key)[...] = np.nan
    assert np.array_equal(model.points, points) and np.array_equal(model.normal, normal)
    assert np.array_equal(solution.forces, forces)
    assert all(np.array_equal(r.normal_forces, b) for r, b in zip(results[1:], before[1:]))
    assert np.all(np.isfinite(results[1].normal)) and np.all(np.isfinite(results[1].shear))


def test_a_model_without_free_blocks_solves_and_has_no_interfaces():
    scene = gen.two_blocks()
    scene = replace(scene, blocks=[replace(b, support=True) for b in scene.blocks])
    model = model_of(scene)
    assert len(model.free) == 0
    solution = solve(model)
    assert solution.solved
    results = interface_results(model, solution, mu_threshold=0.6, tension_tol=1e-5)
    assert len(results) == len(model.interfaces)


def test_csc_helpers_match_scipy():
    rng = np.random.default_rng(1)
    top = sp.random(7, 9, density=0.4, random_state=rng, format="csc")
    bottom = sp.random(5, 9, density=0.3, random_state=rng, format="csc")
    stacked = _Csc.stack(top, bottom).tocsc()
    expected = sp.vstack([top, bottom]).tocsc()
    expected.sort_indices()
    assert stacked.has_canonical_format
    assert np.array_equal(stacked.indptr, expected.indptr)
    assert np.array_equal(stacked.indices, expected.indices)
    assert np.array_equal(stacked.data, expected.data)
    d = np.array([0.0, 2.0, 0.0, 1e6, 1.0])
    assert (_Csc.diagonal(d).tocsc() != sp.diags(d).tocsc()).nnz == 0
    assert _Csc.diagonal(d).tocsc().nnz == 3


_CLARABEL_SOLVER = clarabel.DefaultSolver


class _Spy:
    """Records the settings of every Clarabel solver made."""

    def __init__(self):
        self.settings = []

    def __call__(self, *args):
        self.settings.append(args[-1])
        return _CLARABEL_SOLVER(*args)


def test_first_attempt_skips_refinement_and_balances_the_loads(monkeypatch):
    spy = _Spy()
    monkeypatch.setattr(solver_module.clarabel, "DefaultSolver", spy)
    model = model_of(gen.dome(8, 5))
    solution = solve(model)
    assert solution.solved and solution.residual < 1e-9
    (settings,) = spy.settings
    assert not settings.iterative_refinement_enable
    assert settings.direct_solve_method == "qdldl"


def test_a_solution_short_of_equilibrium_is_solved_again_with_refinement(monkeypatch):
    spy = _Spy()
    monkeypatch.setattr(solver_module.clarabel, "DefaultSolver", spy)
    monkeypatch.setattr(solver_module, "RESIDUAL_TOL", -1.0)   # no attempt is good enough
    model = model_of(stacked_boxes(0.3))
    for options, attempts in ((SolveOptions(), 3), (SolveOptions(friction="plus"), 5)):
        spy.settings.clear()
        solution = solve(model, options)
        assert solution.status == "failed" and len(spy.settings) == attempts
        assert [s.iterative_refinement_enable for s in spy.settings] == [False] + [True] * (
            attempts - 1)
        assert spy.settings[2].static_regularization_constant == solver_module.RETRY_REGULARIZATION


def test_an_ill_conditioned_glued_stack_is_solved_with_a_lower_penalty():
    """A random stack of the long property run: friction+ with the 1e6 tension penalty stops
    short of equilibrium with every setting (AlmostSolved, NumericalError); 100x lower, it
    is solved."""
    from rbe_ros.analysis.pipeline import check_scene
    from rbe_ros.rbe.result import Status
    from rbe_ros.scene import box_block, make_scene
    from scipy.spatial.transform import Rotation

    def box(name, size, centre, yaw, support=False):
        return box_block(name, size, centre, Rotation.from_euler("z", yaw).as_quat(),
                         density=2000.0 if support else 1000.0, support=support)

    scene = make_scene("random", [
        box("ground", (20.0, 20.0, 0.2), (0.0, 0.0, -0.1), 0.0, support=True),
        box("b0", (1.0, 0.25, 1.0), (0.0, 0.0, 0.5), 2.0),
        box("b1", (0.25, 1.0, 1.0), (0.0, 0.5, 1.5), 1.0),
        box("b2", (1.0, 0.5, 1.0), (0.0, 0.5, 2.5), 0.0),
        box("b3", (1.0, 1.0, 1.0), (0.0, 1.0, 3.5), 0.0),
    ], (0.021402082974843712, 0.0, -9.809976653939822))
    report = check_scene(scene)
    assert report.status == Status.TENSION_REQUIRED, report.message
