"""Density cliques of a problem and their budgets of following-type conflicts.

The contract limits crowding per clique of the conflict graph: for every
maximal clique K (networkx), rho_K = min density of its nodes and at most
h_K = rho_K (rho_K + 1) / 2 - 1 of the conflicts inside K may be following-type;
each explicit ``density_limits`` entry adds the same kind of clique with
rho = its ``max_robots``. Only cliques with at least one conflict matter.

Maximal cliques can be exponentially many (a complete multipartite conflict
graph of k robots with n nodes each has n^k), so the enumeration stops with
:class:`TooManyCliques` once the cliques hold more conflicts than the budget
set by :func:`clique_budget`; the service sets it per request, CLIs leave it unbounded.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import networkx as nx
import numpy as np

from service.core.problem import Problem

__all__ = ["Cliques", "TooManyCliques", "budget_for", "clique_budget", "find_cliques"]

# Clique-conflict incidences (the CSR's E) one enumeration may produce; None: unbounded.
_MAX_INCIDENCES: ContextVar[int | None] = ContextVar("max_clique_incidences", default=None)


class TooManyCliques(ValueError):
    """The conflict graph's maximal cliques hold more conflicts than the budget allows."""

    def __init__(self, budget: int) -> None:
        super().__init__(
            "conflict graph too dense: its maximal cliques hold more than "
            f"{budget} conflicts in all (max_clique_incidences)"
        )
        self.budget = budget


@contextmanager
def clique_budget(max_incidences: int | None) -> Iterator[None]:
    """Bound :func:`find_cliques` in this context (thread or task) to ``max_incidences``.

    A context variable rather than a parameter: the enumeration runs deep inside
    whichever solver first needs the cliques, and requests run concurrently.
    """
    token = _MAX_INCIDENCES.set(max_incidences)
    try:
        yield
    finally:
        _MAX_INCIDENCES.reset(token)


def budget_for(rho: int) -> int:
    """h = rho (rho + 1) / 2 - 1: following-type conflicts allowed in a clique of density rho."""
    return rho * (rho + 1) // 2 - 1


@dataclass(frozen=True, eq=False)
class Cliques:
    """Every density clique as a compressed list of its conflicts (CSR layout).

    Shapes: Q cliques, E clique-conflict incidences.
    """

    budget: np.ndarray  # (Q,) int, following-type conflicts allowed in each clique
    edge: np.ndarray  # (E,) int, conflict indices, grouped by clique
    start: np.ndarray  # (Q+1,) int, clique q holds edge[start[q]:start[q+1]]
    n_conflicts: int

    @property
    def size(self) -> np.ndarray:
        """(Q,) int: conflicts inside each clique."""
        return np.diff(self.start)

    @property
    def clique_of_incidence(self) -> np.ndarray:
        """(E,) int: the clique of each incidence."""
        return np.repeat(np.arange(self.budget.size), self.size)

    def forbidden(self) -> np.ndarray:
        """(M,) bool: conflicts inside a zero-budget clique, which must be exclusive."""
        mask = np.zeros(self.n_conflicts, dtype=bool)
        mask[self.edge[self.budget[self.clique_of_incidence] <= 0]] = True
        return mask

    def binding(self) -> np.ndarray:
        """(Q,) bool: cliques whose budget is positive but below their conflict count."""
        return (self.budget > 0) & (self.budget < self.size)

    def following_counts(self, following: np.ndarray) -> np.ndarray:
        """Following-type conflicts inside each clique, for a batch of assignments.

        Shapes: following (S, M) bool -> (S, Q) int.
        """
        following = np.atleast_2d(following)
        if self.budget.size == 0:
            return np.zeros((following.shape[0], 0), dtype=np.int64)
        return np.add.reduceat(following[:, self.edge].astype(np.int64), self.start[:-1], axis=1)


def find_cliques(problem: Problem) -> Cliques:
    """Maximal cliques of the conflict graph plus explicit limits, with budgets.

    Raises:
        TooManyCliques: the cliques exceed the budget of :func:`clique_budget`.
    """
    graph = nx.Graph()
    graph.add_edges_from(zip(problem.conf_a.tolist(), problem.conf_b.tolist(), strict=True))
    density = problem.node_density
    groups = _bounded(nx.find_cliques(graph), _MAX_INCIDENCES.get())
    budgets = [budget_for(int(density[m].min())) for m in groups]
    groups += [lim.nodes.tolist() for lim in problem.density_limits]
    budgets += [budget_for(lim.max_robots) for lim in problem.density_limits]
    edge, start = _incidences(problem, groups)
    return Cliques(
        budget=np.array(budgets, dtype=np.int64),
        edge=edge,
        start=start,
        n_conflicts=problem.n_conflicts,
    )


def _bounded(cliques: Iterator[list[int]], max_incidences: int | None) -> list[list[int]]:
    """Every clique of ``cliques``, stopping as soon as they hold more than ``max_incidences``."""
    groups: list[list[int]] = []
    incidences = 0
    for members in cliques:
        incidences += len(members) * (len(members) - 1) // 2
        if max_incidences is not None and incidences > max_incidences:
            raise TooManyCliques(max_incidences)
        groups.append(members)
    return groups


def _incidences(problem: Problem, groups: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """The conflicts inside each clique of ``groups`` (node lists), in CSR layout.

    Vectorized per clique size: every node pair of a clique is a conflict, looked up
    by :meth:`Problem.conflict_between`.

    Shapes: -> edge (E,) int sorted within each clique, start (Q+1,) int.
    """
    sizes = np.array([len(m) for m in groups], dtype=np.int64)
    start = np.concatenate([[0], np.cumsum(sizes * (sizes - 1) // 2)]).astype(np.int64)
    edge = np.empty(start[-1], dtype=np.int64)
    for size in np.unique(sizes).tolist():
        which = np.flatnonzero(sizes == size)
        members = np.array([groups[q] for q in which], dtype=np.int64)  # (Q_s, size)
        i, j = np.triu_indices(size, 1)
        inside = problem.conflict_between(members[:, i], members[:, j])  # (Q_s, pairs)
        inside = np.sort(inside, axis=1)
        edge[start[which][:, None] + np.arange(i.size)] = inside
    return edge, start
