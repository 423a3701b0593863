"""Graph tensors of a problem for the GNN-VAE (feature layout documented here).

Every feature is a *relative* time divided by the graph's time unit (the
median node duration), clipped to [-CLIP, CLIP]: no absolute clock position
and no dependence on the graph's overall span. So a model trained on small
problems in seconds serves problems in hours and problems of 250 robots whose
span is many times larger (with span-normalized features the first model
generalized poorly to stitched problems: its delay ratio there was ~0.6).

Graph: one vertex per node. Directed edges: precedence v -> v+1 along every
robot's path, then for conflict c the two arcs a -> b (index 2c of the conflict
block) and b -> a (index 2c+1).

Node features (NODE_DIM = 12), per node v of robot r, in units:
  0 duration, 1 log1p(travel before v on its path: enter - T_r(1)),
  2 log1p(travel left after v: T_r(C) - exit), 3 gap from the previous node
  (0 if first), 4 gap to the next node (0 if last), 5 1 / density,
  6 density >= 2, 7 first node, 8 last node, 9 conflicts at v / 8 (clipped to 1),
  10 T_r(C) - mean over robots of T(C), 11 T_r(C) - max over robots of T(C)
  (where r's delay-free finish stands in the fleet: global facts that message
  passing over a few hops cannot gather, and that sync and max completion
  depend on; models before v5 read columns 0-9 only, see GnnVaeConfig).
Edge features (EDGE_DIM = 10), for an arc u -> v, in units:
  0 precedence arc, 1 conflict arc,
  2 pe_v - pe_u (> 0: u's side arrives first), 3 px_u - pe_v (v's wait if u goes
  first, exclusive), 4 px_v - pe_u (u's wait if v goes first), 5 pe_v - enter_v
  and 6 pe_u - enter_u (where the pair section starts inside each node),
  (precedence arcs: 2 = gap between the nodes, 3-6 zero),
  7 following-type forbidden (inside a zero-budget clique),
  8 assignment: +1 if u passes first, -1 if v does (0 on the skeleton graph),
  9 assignment: 1 if following-type (0 on the skeleton graph).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.problem import Problem

__all__ = ["EDGE_DIM", "NODE_DIM", "GraphTensors", "assignment_edge_features", "graph_tensors"]

NODE_DIM = 12
EDGE_DIM = 10
ASSIGN_COLS = slice(8, 10)
CLIP = 10.0  # relative times beyond 10 time units carry no extra information


@dataclass(frozen=True)
class GraphTensors:
    """Skeleton-graph tensors of one problem.

    Shapes: x (V, NODE_DIM); edge_index (2, Ep + 2M); edge_attr (Ep + 2M, EDGE_DIM);
    conf (M, 2) long node indices (side a, side b).
    """

    x: torch.Tensor
    edge_index: torch.Tensor
    edge_attr: torch.Tensor
    conf: torch.Tensor
    n_precedence: int


def _time_unit(problem: Problem) -> float:
    """The graph's time unit: the median node duration (positive by the input rules)."""
    return float(np.median(problem.node_exit - problem.node_enter))


def _node_features(problem: Problem, unit: float) -> np.ndarray:
    """(V, NODE_DIM) float32, see the module doc."""
    first = np.zeros(problem.n_nodes, dtype=bool)
    first[problem.robot_start[:-1]] = True
    last = np.zeros(problem.n_nodes, dtype=bool)
    last[problem.robot_start[1:] - 1] = True
    start = problem.tp_time[problem.tp_start[:-1]][problem.node_robot]  # (V,) T_r(1)
    robot_free = problem.free_time()  # (R,) T_r(C)
    free = robot_free[problem.node_robot]  # (V,) T_r(C) of the node's robot
    gap_before = np.zeros(problem.n_nodes)
    gap_before[~first] = (problem.node_enter[1:] - problem.node_exit[:-1])[~first[1:]]
    gap_after = np.zeros(problem.n_nodes)
    gap_after[~last] = gap_before[np.flatnonzero(~last) + 1]
    degree = np.bincount(problem.conf_nodes.ravel(), minlength=problem.n_nodes)
    x = np.stack(
        [
            (problem.node_exit - problem.node_enter) / unit,
            np.log1p((problem.node_enter - start) / unit),
            np.log1p((free - problem.node_exit) / unit),
            gap_before / unit,
            gap_after / unit,
            1.0 / problem.node_density,
            problem.node_density >= 2,
            first,
            last,
            np.minimum(degree / 8.0, 1.0),
            (free - robot_free.mean()) / unit,
            (free - robot_free.max()) / unit,
        ],
        axis=1,
    )
    return np.clip(x, -CLIP, CLIP).astype(np.float32)


def _conflict_features(problem: Problem, cliques: Cliques, unit: float) -> np.ndarray:
    """(2M, EDGE_DIM) float32 for the arcs a -> b, b -> a of every conflict."""
    pe, px = problem.pair_enter, problem.pair_exit  # (M, 2) sides a, b
    node_enter = problem.node_enter[problem.conf_nodes]  # (M, 2)
    # Arc 2c is a -> b (u = side a, v = side b); arc 2c+1 is b -> a.
    pe_u, pe_v = pe.ravel(), pe[:, ::-1].ravel()
    px_u, px_v = px.ravel(), px[:, ::-1].ravel()
    en_u, en_v = node_enter.ravel(), node_enter[:, ::-1].ravel()
    attr = np.zeros((pe_u.size, EDGE_DIM))
    attr[:, 1] = 1.0
    attr[:, 2] = (pe_v - pe_u) / unit
    attr[:, 3] = (px_u - pe_v) / unit
    attr[:, 4] = (px_v - pe_u) / unit
    attr[:, 5] = (pe_v - en_v) / unit
    attr[:, 6] = (pe_u - en_u) / unit
    attr[:, 7] = np.repeat(cliques.forbidden(), 2)
    return np.clip(attr, -CLIP, CLIP).astype(np.float32)


def graph_tensors(problem: Problem, cliques: Cliques) -> GraphTensors:
    """Features and arcs of ``problem``'s skeleton graph (assignment columns zero)."""
    unit = _time_unit(problem)
    last = np.zeros(problem.n_nodes, dtype=bool)
    last[problem.robot_start[1:] - 1] = True
    prec = np.flatnonzero(~last)  # (Ep,) arcs v -> v+1
    prec_attr = np.zeros((prec.size, EDGE_DIM), dtype=np.float32)
    prec_attr[:, 0] = 1.0
    prec_attr[:, 2] = np.clip(
        (problem.node_enter[prec + 1] - problem.node_exit[prec]) / unit, 0, CLIP
    )
    src = np.stack([problem.conf_a, problem.conf_b], axis=1).ravel()  # (2M,) a->b, b->a
    dst = np.stack([problem.conf_b, problem.conf_a], axis=1).ravel()
    edge_index = np.concatenate([np.stack([prec, prec + 1]), np.stack([src, dst])], axis=1)
    attr = np.concatenate([prec_attr, _conflict_features(problem, cliques, unit)])
    return GraphTensors(
        x=torch.from_numpy(_node_features(problem, unit)),
        edge_index=torch.from_numpy(edge_index.astype(np.int64)),
        edge_attr=torch.from_numpy(attr),
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
