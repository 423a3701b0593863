"""The one constraint checker: every answer of every solver passes through it.

It is deliberately independent of the decoder: acyclicity is checked by a
topological sort (stdlib ``graphlib``) of the node graph, density by counting
following-type conflicts per clique, and fixed directions by comparing each
fixed conflict's direction with its ``first``.
"""

from __future__ import annotations

from dataclasses import dataclass
from graphlib import CycleError, TopologicalSorter

import numpy as np

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.problem import Problem

__all__ = ["CheckResult", "check", "is_acyclic"]


@dataclass(frozen=True)
class CheckResult:
    """Per-sample results. Shapes: acyclic, density, forced (S,) bool each.

    ``forced``: the assignment agrees with every fixed direction and fixed type.
    """

    acyclic: np.ndarray
    density: np.ndarray
    forced: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """(S,) bool: every constraint holds."""
        return self.acyclic & self.density & self.forced


def is_acyclic(problem: Problem, first: np.ndarray, second: np.ndarray) -> bool:
    """True when path order plus the conflict arcs first -> second (M,) form a DAG."""
    graph: dict[int, set[int]] = {v: set() for v in range(problem.n_nodes)}
    chain = np.flatnonzero(problem.node_robot[1:] == problem.node_robot[:-1])
    for v in chain.tolist():
        graph[v + 1].add(v)
    for u, v in zip(first.tolist(), second.tolist(), strict=True):
        graph[v].add(u)
    try:
        tuple(TopologicalSorter(graph).static_order())
    except CycleError:
        return False
    return True


def check(problem: Problem, cliques: Cliques, assignments: Assignments) -> CheckResult:
    """Check node-level acyclicity, every clique's following budget, fixed directions and
    fixed types (the realized conflicts of a re-schedule)."""
    acyclic = np.array(
        [
            is_acyclic(problem, *assignments.from_to(problem, s))
            for s in range(assignments.n_samples)
        ],
        dtype=bool,
    )
    counts = cliques.following_counts(assignments.following)  # (S, Q)
    density = np.all(counts <= cliques.budget[None, :], axis=1)
    fixed = np.flatnonzero(problem.forced)  # (F,)
    wanted = problem.forced[fixed] > 0  # (F,) side a first
    forced = np.all(assignments.a_first[:, fixed] == wanted[None, :], axis=1)  # (S,)
    typed = np.flatnonzero(problem.fixed_type >= 0)  # (F',)
    wanted_type = problem.fixed_type[typed] == 1  # (F',) following
    forced &= np.all(assignments.following[:, typed] == wanted_type[None, :], axis=1)
    return CheckResult(acyclic, density, forced)
