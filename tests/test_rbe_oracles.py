"""The equilibrium model, the solver and the verdict's rules against closed forms, written for
mutants that survived the rest of the suite (docs/MUTATION.md): known wrenches on a box,
sliding boxes on slopes (tan alpha), the sliding flags, failed solves, the names of
floating blocks and the CSC helper."""
import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from rbe_ros.analysis import verdict
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.verdict import _flag_sliding, infeasible_report, stable_forces
from rbe_ros.rbe.model import build_model
from rbe_ros.rbe.result import Status
from rbe_ros.rbe.solver import Solution, SolveOptions, _Csc
from rbe_ros.scene import box_block, make_scene

from helpers import DENSITY, checked, inclined_block, stacked_boxes
from test_core_units import slopes_and_flat

G = 9.81


def two_boxes_on_the_ground():
    return make_scene("two", [
        box_block("ground", (6, 2, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        box_block("a", (1, 1, 1), (-1.5, 0, 0.5), density=DENSITY),
        box_block("b", (1, 1, 1), (1.5, 0, 0.5), density=DENSITY)])


@pytest.mark.parametrize("force, mx, my", [(0.0, 0.0, 0.0), (3000.0, 0.0, 0.0),
                                           (2000.0, 500.0, -800.0)])
def test_a_known_wrench_moves_the_resultant_by_its_moment_over_the_normal_force(force, mx, my):
    """A downward force F and a moment (Mx, My) about b's centroid, on top of the weights:
    b's base carries N = m g + F at the centroid shifted by (My / N, -Mx / N) (moment
    balance about the centroid); a, not loaded, keeps m g at its own centroid."""
    assembly = Assembly.from_scene(two_boxes_on_the_ground())
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    b = [blk.id for blk in assembly.blocks].index("b")
    wrench = {b: np.array([0.0, 0.0, -force, mx, my, 0.0])}
    found = stable_forces(model, CheckOptions(), model.dead_load + model.wrench_load(wrench))
    assert found is not None
    by_block = {r.block_b: r for r in found[1]}
    weight = DENSITY * G
    n = weight + force
    assert by_block["b"].normal_resultant == pytest.approx(n, rel=1e-7)
    assert np.allclose(by_block["b"].centre_of_pressure, [1.5 + my / n, -mx / n, 0.0],
                       rtol=0, atol=1e-7)
    assert by_block["a"].normal_resultant == pytest.approx(weight, rel=1e-7)
    assert np.allclose(by_block["a"].centre_of_pressure, [-1.5, 0.0, 0.0], rtol=0, atol=1e-7)


def test_sliding_flags_every_interface_over_the_cone_even_under_a_higher_threshold():
    """Boxes on 20 and 25 deg slopes need mu >= tan 20 = 0.364 and tan 25 = 0.466: at
    mu 0.3 both slide, and both are flagged although the post-check threshold (2) flags
    neither; the box on flat ground is not."""
    report = checked(slopes_and_flat(), CheckOptions(SolveOptions(mu=0.3), mu_threshold=2.0))
    assert report.status == Status.FRICTION_EXCEEDED
    flags = {r.block_b: r.friction_exceeded for r in report.interfaces}
    assert flags == {"s20_box": True, "s25_box": True, "flat": False}
    ratios = {r.block_b: r.friction_ratio for r in report.interfaces}
    assert ratios["s20_box"] == pytest.approx(math.tan(math.radians(20)), rel=1e-6)
    assert ratios["s25_box"] == pytest.approx(math.tan(math.radians(25)), rel=1e-6)


def test_sliding_through_torsion_alone_flags_the_highest_ratio():
    """When the vertex cones fail while no resultant exceeds the capacity (torsion), the
    interface asking most friction is the one flagged; none for no interfaces."""
    results = [r for r in checked(slopes_and_flat()).interfaces]
    ratios = [0.2, 0.5, 0.1]
    results = [replace(r, friction_ratio=q, friction_exceeded=False)
               for r, q in zip(results, ratios)]
    flagged = _flag_sliding(results, 0.6)
    assert [r.friction_exceeded for r in flagged] == [False, True, False]
    assert [r.friction_exceeded for r in _flag_sliding(results, 0.15)] == [True, True, False]
    assert _flag_sliding([], 0.6) == []


def test_a_failed_solve_is_no_infeasibility_to_explain():
    """A solve out of time is a failure, not a proof that the assembly cannot stand."""
    options = CheckOptions(SolveOptions(time_limit=1e-9))
    assert infeasible_report(Assembly.from_scene(inclined_block(10.0)), options) is None


def test_a_glued_solve_that_fails_is_reported_as_failed(monkeypatch):
    """Boxes that tip (no equilibrium without tension, none with unlimited friction): when
    the glued friction+ solve that would show where fails, the report is SOLVER_FAILED with
    the solver's status, not a verdict."""
    real = verdict.solve

    def glue_fails(model, options, **kwargs):
        if options.friction == "plus":
            return Solution("failed", "MaxTime", np.zeros((4, model.num_vertices)), 0.0)
        return real(model, options, **kwargs)

    monkeypatch.setattr(verdict, "solve", glue_fails)
    report = infeasible_report(Assembly.from_scene(stacked_boxes(0.6)), CheckOptions())
    assert report.status == Status.SOLVER_FAILED
    assert report.message == "solver failed: MaxTime"


@pytest.mark.parametrize("mu, stands", [(0.3, False), (0.4, True)])
def test_stable_forces_solve_with_the_options_mu(mu, stands):
    """A box on a 20 deg slope needs mu >= tan 20 = 0.364, whatever the post-check threshold
    (2 here) would let through."""
    assembly = Assembly.from_scene(inclined_block(20.0))
    model = build_model(assembly.blocks, assembly.interfaces, assembly.gravity)
    found = stable_forces(model, CheckOptions(SolveOptions(mu=mu), mu_threshold=2.0))
    assert (found is not None) is stands
    if stands:
        assert found[1][0].friction_ratio == pytest.approx(math.tan(math.radians(20)), rel=1e-6)


@pytest.mark.parametrize("count, shown", [(5, "blocks f0, f1, f2, f3, f4 not"),
                                          (6, "blocks f0, f1, f2, f3, f4 and 1 more not")])
def test_five_floating_blocks_are_named_in_full_and_a_sixth_is_counted(count, shown):
    report = checked(make_scene("s", [
        box_block("ground", (20, 20, 0.2), (0, 0, -0.1), support=True, density=DENSITY),
        *[box_block(f"f{k}", (1, 1, 1), (3.0 * k, 0, 3.0), density=DENSITY)
          for k in range(count)]]))
    assert report.message == f"no equilibrium: {shown} connected to a support by any contact"


def test_a_diagonal_with_trailing_zeros_keeps_its_shape():
    d = np.array([1.0, 0.0, 2.0, 0.0])
    csc = _Csc.diagonal(d).tocsc()
    assert csc.shape == (4, 4) and (csc != sp.diags(d).tocsc()).nnz == 0
