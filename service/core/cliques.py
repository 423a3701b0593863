"""Density cliques of a problem and their budgets of following-type conflicts.

The contract limits crowding per clique of the conflict graph: for every
maximal clique K (networkx), rho_K = min density of its nodes and at most
h_K = rho_K (rho_K + 1) / 2 - 1 of the conflicts inside K may be following-type;
each explicit ``density_limits`` entry adds the same kind of clique with
rho = its ``max_robots``. Only cliques with at least one conflict matter.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np

from service.core.problem import Problem

__all__ = ["Cliques", "budget_for", "find_cliques"]


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
    """Maximal cliques of the conflict graph plus explicit limits, with budgets."""
    pair_index = {
        (a, b): k
        for k, (a, b) in enumerate(
            zip(problem.conf_a.tolist(), problem.conf_b.tolist(), strict=True)
        )
    }
    pair_index.update({(b, a): k for (a, b), k in list(pair_index.items())})
    graph = nx.Graph()
    graph.add_edges_from(pair_index)
    groups: list[tuple[list[int], int]] = []
    density = problem.node_density
    for members in nx.find_cliques(graph):
        groups.append((members, budget_for(int(density[members].min()))))
    for lim in problem.density_limits:
        groups.append((lim.nodes.tolist(), budget_for(lim.max_robots)))
    edges: list[list[int]] = [
        [pair_index[(u, v)] for i, u in enumerate(m) for v in m[i + 1 :]] for m, _ in groups
    ]
    counts = np.array([len(e) for e in edges], dtype=np.int64)
    return Cliques(
        budget=np.array([h for _, h in groups], dtype=np.int64),
        edge=np.array([k for e in edges for k in sorted(e)], dtype=np.int64),
        start=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        n_conflicts=problem.n_conflicts,
    )
