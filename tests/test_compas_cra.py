"""Our RBE solve against compas_cra 0.8.0's own ``rbe_solve`` on the samples it ships.

compas-cra is no dependency of this project: the test runs only when $RBE_COMPAS_VENV names a
venv that has it (``python3 benchmarks/compas_compare.py`` makes one, /tmp/rbe-compas-venv by
default) or when this interpreter imports compas_cra; otherwise it is skipped. It uses the
benchmark's own functions (benchmarks/compas_compare.py): compas_cra detects and solves in
its venv, we solve on its interface polygons with its settings (friction+, circumscribed
8-sided pyramid in its interface frames, weights 1 / 1e6 / 1).

The samples are those where compas_cra's answer is the minimiser of the objective it states:
elsewhere (shelf, bridge, armadillo) its ``_tilde_weights`` leaves fv unweighted on two
vertices in three, which changes the answer by 4-27 % (docs/COMPAS.md); the last test pins
that explanation on the shelf.
"""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import compas_compare as cc

CRA_PYTHON = cc.cra_python_from_env()
pytestmark = pytest.mark.skipif(
    CRA_PYTHON is None, reason=f"compas_cra {cc.CRA_VERSION} not available (set {cc.VENV_ENV} to a"
                               " venv with compas-cra, e.g. the one benchmarks/compas_compare.py makes)")

SAMPLES = ("cubes", "A", "H", "snake")
DIAGNOSED = ("shelf",)


@pytest.fixture(scope="module")
def cra(tmp_path_factory):
    out = tmp_path_factory.mktemp("compas") / "cra.json"
    return cc.run_driver(CRA_PYTHON, SAMPLES + DIAGNOSED, out, repeat=1)["samples"]


@pytest.fixture(scope="module")
def compared(cra):
    return {name: cc.compare_sample(record, repeat=1) for name, record in cra.items()}


@pytest.mark.parametrize("name", SAMPLES)
def test_normal_resultants_agree_with_rbe_solve(compared, name):
    r = compared[name]
    assert r["cra_residual_in_our_model"] < 1e-9          # its forces balance our blocks
    assert r["volume_rel_err"] < 1e-6
    assert r["agreement"] <= cc.TOLERANCE, r["normal_resultants"]


def test_at_least_three_samples_agree(compared):
    assert sum(compared[n]["agreement"] <= cc.TOLERANCE for n in SAMPLES) >= 3


def test_shelf_difference_is_compas_cra_fv_weighting(compared):
    r = compared["shelf"]
    # as shipped it differs, but not once its fv weights are fixed (and IPOPT solves tightly),
    # and our solver with its weighting imitated lands on its answer
    assert r["agreement"] > cc.TOLERANCE
    assert r["agreement_fixed_weights_strict"] < 1e-3
    if r["agreement_ours_with_cra_weights_strict"] is None:
        pytest.skip("the solver's objective can no longer be wrapped to imitate compas_cra's weights")
    assert r["agreement_ours_with_cra_weights_strict"] < 1e-3
