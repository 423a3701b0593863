"""Suite-wide fixtures."""

from __future__ import annotations

import pytest

from service.api.runtime import warm_solvers
from service.solvers.dispatch import DispatchPolicy


@pytest.fixture(scope="session", autouse=True)
def compiled_search_kernels() -> None:
    """Every solver's kernels compiled (or loaded from numba's cache) once, before any
    test, as the service's warm-up does before it reports ready: compiling re-insertion
    search's alone takes ~15 s on a fresh machine, which would otherwise land in whichever
    timed test first reaches it."""
    warm_solvers(DispatchPolicy())
