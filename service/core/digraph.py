"""Directed graphs over nodes 0..n-1 given as arc arrays: components and acyclicity.

Strongly connected components come from scipy's compiled implementation
(Pearce's algorithm): a graph without self-loops is a DAG exactly when every
component is a single node. The checker and the problem's validation of fixed
directions use it; it is a different algorithm from the decoder's topological
sort, so the checker stays independent of the decoder.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_array
from scipy.sparse.csgraph import connected_components

__all__ = ["components", "is_dag", "path_arcs"]


def path_arcs(node_robot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) tails and heads of the path-order arcs between consecutive nodes of a robot
    (node indices increase along each robot's path)."""
    chain = np.flatnonzero(node_robot[1:] == node_robot[:-1])
    return chain, chain + 1


def components(n_nodes: int, *arcs: np.ndarray) -> tuple[int, np.ndarray]:
    """Strongly connected components of a graph given as tail, head arrays (pairs of
    (K_i,) arrays) -> (count, (n_nodes,) component label)."""
    tails, heads = np.concatenate(arcs[0::2]), np.concatenate(arcs[1::2])
    graph = coo_array(
        (np.ones(tails.size, dtype=np.int8), (tails, heads)), shape=(n_nodes, n_nodes)
    )
    return connected_components(graph, directed=True, connection="strong")


def is_dag(n_nodes: int, *arcs: np.ndarray) -> bool:
    """Whether the arcs (tail, head array pairs, never a self-loop) leave no cycle."""
    count, _ = components(n_nodes, *arcs)
    return count == n_nodes
