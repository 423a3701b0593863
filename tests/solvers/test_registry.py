"""The solver registry."""

from __future__ import annotations

import pytest

from service.solvers import dispatch  # noqa: F401  (registers every solver)
from service.solvers.registry import get_solver, register, solver_names


def test_solvers_are_registered() -> None:
    assert {"exact", "fcfs"} <= set(solver_names())


def test_unknown_solver() -> None:
    with pytest.raises(KeyError):
        get_solver("no-such-solver")


def test_registering_a_name_twice_fails() -> None:
    before = get_solver("fcfs")
    with pytest.raises(ValueError, match="twice"):
        register("fcfs")(lambda ctx: None)
    assert get_solver("fcfs") is before
