"""Suite-wide fixtures."""

from __future__ import annotations

import pytest

from service.api.runtime import warm_solver
from service.solvers.dispatch import DispatchPolicy


@pytest.fixture(scope="session", autouse=True)
def compiled_search_kernels() -> None:
    """Re-insertion search's kernels compiled (or loaded from numba's cache) once, before
    any test, as the service's warm-up does before it reports ready: compiling them takes
    ~15 s on a fresh machine, which would otherwise land in whichever timed test first
    reaches the re-insertion stage of ``auto``."""
    warm_solver(DispatchPolicy(), "reinsert", 0.2)
