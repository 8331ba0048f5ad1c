"""Our RBE solve against compas_cra 0.8.0's own ``rbe_solve`` on the samples it ships.

compas-cra is no dependency of .venv: it lives in .venv-compas, which scripts/setup.sh builds
(or the venv $RBE_COMPAS_VENV names); without it the tests fail, they never skip. It uses the
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


SAMPLES = ("cubes", "A", "H", "snake")
DIAGNOSED = ("shelf",)


@pytest.fixture(scope="module")
def cra(tmp_path_factory):
    python = cc.cra_python_from_env()
    assert python is not None, f"no compas_cra {cc.CRA_VERSION}: run make setup (it builds .venv-compas)"
    out = tmp_path_factory.mktemp("compas") / "cra.json"
    return cc.run_driver(python, SAMPLES + DIAGNOSED, out, repeat=1)["samples"]


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
    assert r["agreement_ours_with_cra_weights_strict"] is not None   # the imitation solved
    assert r["agreement_ours_with_cra_weights_strict"] < 1e-3
