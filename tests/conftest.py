"""Shared pytest configuration: hypothesis profiles and data locations.

Profiles
--------
``dev``  quick local runs (default outside CI): few examples, no deadline.
``ci``   selected automatically when ``CI=true``: more examples, derandomised so a
         failure in CI is reproducible from the log, still well inside the CI budget.
Select explicitly with ``HYPOTHESIS_PROFILE=ci pytest`` or ``pytest --hypothesis-profile=ci``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "dev",
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "ci",
    max_examples=300,
    deadline=None,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
_default = "ci" if os.environ.get("CI", "").lower() in {"1", "true", "yes"} else "dev"
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", _default))

REPO_ROOT = Path(__file__).resolve().parent.parent
SHARED_DATA = REPO_ROOT.parent / "shared" / "data"
"""Where the project's original copies of the real problems live (beside the repository, not
shipped); the tests read the byte-identical copies bundled in ``rfverify/data/`` instead, so a
fresh clone runs every test (``tests/test_files.py`` pins their checksums)."""


@pytest.fixture(scope="session")
def real_data() -> Path:
    """Directory of the real problem files: the copies bundled with rfverify (``rfverify/data/``:
    the Siconos Chute FCLIB file and the Siconos ``.dat`` problems)."""
    from rfverify import data

    return Path(data.__file__).resolve().parent


@pytest.fixture(autouse=True)
def _restore_numpy_errstate():
    """Fail loudly if a test leaks a changed numpy floating-point error state."""
    before = np.geterr()
    yield
    after = np.geterr()
    np.seterr(**before)
    assert after == before, f"test changed numpy error state: {before} -> {after}"


@pytest.fixture(autouse=True)
def _mpmath_precision_is_restored():
    """Fail loudly if a test leaks a changed global mpmath precision (``mpmath.mp.prec``).

    The reference implementation must never change the global precision (it computes in the
    context of its inputs); tests that need another precision use a private
    ``mpmath.MPContext()`` or ``mpmath.workprec``/``workdps``, which restore it.  Like
    mpmath's own conftest (which resets ``mp.dps`` before every test) the precision is
    restored either way, so one leak does not cascade into later tests; unlike it, the test
    that leaked fails.
    """
    import mpmath

    before = mpmath.mp.prec
    yield
    after = mpmath.mp.prec
    mpmath.mp.prec = before
    assert after == before, f"test changed mpmath.mp.prec: {before} -> {after}"


@pytest.fixture(params=["cholmod", "qdldl"])
def schur_engine(request, monkeypatch) -> str:
    """Each test twice, once per engine of the ``schur`` form: CHOLMOD (cvxopt, a dependency:
    never skipped) and QDLDL, the fallback of an install without cvxopt (made unimportable: a
    None entry in sys.modules stops an import).  The value is the engine's name as the solver
    log gives it."""
    if request.param == "cholmod":
        return "CHOLMOD"
    block_cvxopt(monkeypatch)
    return "QDLDL"


def block_cvxopt(monkeypatch):
    """Make ``import cvxopt`` fail for one test, as on an install without it."""
    monkeypatch.setitem(sys.modules, "cvxopt", None)
    monkeypatch.setitem(sys.modules, "cvxopt.cholmod", None)
