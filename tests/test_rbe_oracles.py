"""The equilibrium model, the solver and the verdict's rules against closed forms, written for
mutants that survived the rest of the suite (docs/MUTATION.md): known wrenches on a box."""
import numpy as np
import pytest

from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.verdict import stable_forces
from rbe_ros.rbe.model import build_model
from rbe_ros.scene import box_block, make_scene

from helpers import DENSITY

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
