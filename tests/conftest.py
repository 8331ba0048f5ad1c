"""Hypothesis profiles of the property tests (tests/test_properties.py).

``ci`` (default): 100 examples per property test (5 tests: 500 generated scenes),
derandomized and without an example database, so every run checks the same scenes.
``long``: 2,000 examples per test (10,000 scenes, random, 5-15 minutes on 2 cores):
``HYPOTHESIS_PROFILE=long make test-long``. ``dev``: 20 examples per test, for a quick look;
``mutation``: 10, derandomized (scripts/mutation.py).

The compas_cra comparison (tests/test_compas_cra.py, the real samples of test_compas_io.py)
uses .venv-compas, which scripts/setup.sh builds, unless $RBE_COMPAS_VENV and
$RBE_COMPAS_SAMPLES name others; those tests fail, never skip, when it is missing.

Tests marked ``long`` (minutes each: whole suites planned or checked against references) are
left out of ``make test`` (``-m "not long"``) and run by ``make test-long``. ``make test`` runs
the core tests on both cores (pytest-xdist), then the ROS tests (tests/ros), which start
nodes and time their answers, on both cores by test file (``--dist loadfile``).
"""
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from rbe_ros.io.compas import compas_samples_dir

_COMMON = dict(deadline=None, database=None, print_blob=True,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
settings.register_profile("ci", max_examples=100, derandomize=True, **_COMMON)
settings.register_profile("long", max_examples=2000, **_COMMON)
settings.register_profile("dev", max_examples=20, **_COMMON)
settings.register_profile("mutation", max_examples=10, derandomize=True, **_COMMON)  # make mutation
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


def pytest_configure(config):
    config.addinivalue_line("markers", "long: minutes long; make test-long runs it, make test not")


COMPAS_VENV = Path(__file__).resolve().parents[1] / ".venv-compas"
os.environ.setdefault("RBE_COMPAS_VENV", str(COMPAS_VENV))
os.environ.setdefault("RBE_COMPAS_SAMPLES", str(next(
    COMPAS_VENV.glob("lib/python*/site-packages/compas_cra/data/samples"), COMPAS_VENV)))


@pytest.fixture(scope="session")
def samples() -> Path:
    """compas_cra's sample assemblies (from .venv-compas, which make setup builds)."""
    found = compas_samples_dir()
    assert found is not None and all((found / f"{n}.json").is_file() for n in ("A", "bridge")), \
        "compas_cra's samples are missing: run make setup (it builds .venv-compas)"
    return found
