"""Graph tensors of a problem for the GNN-VAE (feature layout documented here).

Times are normalized per graph, t_n = (t - t_min) / span with span the
graph's time span, so a model trained on one time scale serves any other.

Graph: one vertex per node. Directed edges: precedence v -> v+1 along every
robot's path, then for conflict c the two arcs a -> b (index 2c of the conflict
block) and b -> a (index 2c+1).

Node features (NODE_DIM = 10), per node v of robot r:
  0 enter_n, 1 exit_n, 2 (exit - enter) / span, 3 robot's free completion T_r(C)_n,
  4 (T_r(C) - exit) / span (travel left after v), 5 1 / density,
  6 density >= 2, 7 first node of its robot, 8 last node of its robot,
  9 conflicts at v / 8 (degree, clipped to 1).
Edge features (EDGE_DIM = 9), for an arc u -> v:
  0 precedence arc, 1 conflict arc,
  2 pair enter_n of v's side, 3 pair exit_n of v's side,
  4 pair enter_n of u's side, 5 pair exit_n of u's side
    (precedence arcs: 2 = gap (enter_v - exit_u) / span, 3-5 zero),
  6 following-type forbidden (inside a zero-budget clique),
  7 assignment: +1 if u passes first, -1 if v does (0 on the skeleton graph),
  8 assignment: 1 if following-type (0 on the skeleton graph).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.problem import Problem

__all__ = ["EDGE_DIM", "NODE_DIM", "GraphTensors", "assignment_edge_features", "graph_tensors"]

NODE_DIM = 10
EDGE_DIM = 9
ASSIGN_COLS = slice(7, 9)


@dataclass(frozen=True)
class GraphTensors:
    """Skeleton-graph tensors of one problem.

    Shapes: x (V, NODE_DIM); edge_index (2, Ep + 2M); edge_attr (Ep + 2M, EDGE_DIM);
    robot_of_node (V,) long; conf (M, 2) long node indices (side a, side b).
    """

    x: torch.Tensor
    edge_index: torch.Tensor
    edge_attr: torch.Tensor
    robot_of_node: torch.Tensor
    conf: torch.Tensor
    n_precedence: int


def graph_tensors(problem: Problem, cliques: Cliques) -> GraphTensors:
    """Features and arcs of ``problem``'s skeleton graph (assignment columns zero)."""
    t = problem.tp_time
    t0 = float(t.min())
    span = max(float(t.max()) - t0, 1e-9)

    def norm(v: np.ndarray) -> np.ndarray:
        return (v - t0) / span

    free = problem.free_time()[problem.node_robot]  # (V,)
    first = np.zeros(problem.n_nodes, dtype=bool)
    first[problem.robot_start[:-1]] = True
    last = np.zeros(problem.n_nodes, dtype=bool)
    last[problem.robot_start[1:] - 1] = True
    degree = np.bincount(problem.conf_nodes.ravel(), minlength=problem.n_nodes)
    x = np.stack(
        [
            norm(problem.node_enter),
            norm(problem.node_exit),
            (problem.node_exit - problem.node_enter) / span,
            norm(free),
            (free - problem.node_exit) / span,
            1.0 / problem.node_density,
            problem.node_density >= 2,
            first,
            last,
            np.minimum(degree / 8.0, 1.0),
        ],
        axis=1,
    ).astype(np.float32)

    prec = np.flatnonzero(~last)  # (Ep,) arcs v -> v+1
    prec_attr = np.zeros((prec.size, EDGE_DIM), dtype=np.float32)
    prec_attr[:, 0] = 1.0
    prec_attr[:, 2] = (problem.node_enter[prec + 1] - problem.node_exit[prec]) / span

    m = problem.n_conflicts
    a, b = problem.conf_a, problem.conf_b
    src = np.stack([a, b], axis=1).ravel()  # (2M,) a->b, b->a
    dst = np.stack([b, a], axis=1).ravel()
    pe, px = norm(problem.pair_enter), norm(problem.pair_exit)  # (M, 2) sides a, b
    conf_attr = np.zeros((2 * m, EDGE_DIM), dtype=np.float32)
    conf_attr[:, 1] = 1.0
    conf_attr[:, 2] = pe[:, ::-1].ravel()  # v's side: b for a->b, a for b->a
    conf_attr[:, 3] = px[:, ::-1].ravel()
    conf_attr[:, 4] = pe.ravel()
    conf_attr[:, 5] = px.ravel()
    conf_attr[:, 6] = np.repeat(cliques.forbidden(), 2)

    edge_index = np.concatenate([np.stack([prec, prec + 1]), np.stack([src, dst])], axis=1)
    return GraphTensors(
        x=torch.from_numpy(x),
        edge_index=torch.from_numpy(edge_index.astype(np.int64)),
        edge_attr=torch.from_numpy(np.concatenate([prec_attr, conf_attr])),
        robot_of_node=torch.from_numpy(problem.node_robot.astype(np.int64)),
        conf=torch.from_numpy(problem.conf_nodes.astype(np.int64)),
        n_precedence=int(prec.size),
    )


def assignment_edge_features(graph: GraphTensors, assignment: Assignments) -> torch.Tensor:
    """Edge features with the assignment columns filled from its first sample.

    Shapes: -> (Ep + 2M, EDGE_DIM).
    """
    attr = graph.edge_attr.clone()
    a_first = torch.from_numpy(assignment.a_first[0].astype(np.float32))  # (M,)
    follow = torch.from_numpy(assignment.following[0].astype(np.float32))  # (M,)
    sign = torch.stack([2 * a_first - 1, 1 - 2 * a_first], dim=1).reshape(-1)  # (2M,)
    block = attr[graph.n_precedence :]
    block[:, ASSIGN_COLS.start] = sign
    block[:, ASSIGN_COLS.start + 1] = follow.repeat_interleave(2)
    return attr
