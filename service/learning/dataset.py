"""Training examples: dataset records -> PyG ``Data`` graphs with one target assignment each.

Each problem keeps its skeleton tensors and its top-L targets for one
objective; every epoch draws one target per problem uniformly, so over epochs
the model sees the whole distribution of best assignments (the VAE's job is to
represent that distribution, not a single optimum). A :class:`TargetFilter`
drops targets by the quality their labeller proved: large problems' labels are
the best known answer with CP-SAT's relative gap, not proven optima.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch_geometric.data import Data

from service.core.assignment import Assignments
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder
from service.core.evaluate import Evaluator
from service.core.lazy import cached_property
from service.core.problem import Problem, problem_from_request
from service.core.schemas import Objective, ScheduleRequest
from service.learning.features import GraphTensors, assignment_edge_features, graph_tensors

__all__ = ["KEEP_ALL", "Example", "TargetFilter", "examples_from_records", "target_gap", "to_data"]


@dataclass(eq=False)
class Example:
    """One problem with its skeleton tensors and its best assignments for one objective."""

    problem: Problem
    cliques: Cliques
    graph: GraphTensors
    targets: list[Assignments]
    opt_cost: float

    @cached_property
    def decoder(self) -> Decoder:
        return Decoder(self.problem, self.cliques)

    @cached_property
    def evaluator(self) -> Evaluator:
        return Evaluator(self.problem)


def target_gap(target: dict[str, Any]) -> float | None:
    """A stored target's relative gap to the best bound: 0 when proven optimal, the labeller's
    ``gap`` otherwise, None when unknown (no bound found, or a dataset from before gaps were
    recorded, whose unproven targets carry none)."""
    return 0.0 if target["optimal"] else target.get("gap")


@dataclass(frozen=True)
class TargetFilter:
    """Which stored targets training keeps, by the gap their labeller proved.

    ``max_gap``: drop targets whose relative gap exceeds it (None: any gap);
    ``proven_only``: drop targets whose gap is unknown (kept by default: such a label is
    still the best answer its labeller found, only nothing bounds how far from optimal).
    With ``max_gap=0`` and ``proven_only`` only proven optima remain.

    Example: ``TargetFilter(max_gap=0.05)`` keeps proven optima, labels within 5 % of
    their bound, and labels of unknown gap.
    """

    max_gap: float | None = None
    proven_only: bool = False

    def keeps(self, target: dict[str, Any]) -> bool:
        """Whether training uses ``target``."""
        gap = target_gap(target)
        if gap is None:
            return not self.proven_only
        return self.max_gap is None or gap <= self.max_gap


KEEP_ALL = TargetFilter()  # every target: what training did before targets had gaps


def _bits(text: str) -> np.ndarray:
    return np.frombuffer(text.encode(), dtype=np.uint8) == ord("1")


def examples_from_records(
    records: Iterable[dict[str, Any]],
    objective: Objective,
    max_targets: int | None = None,
    keep: TargetFilter = KEEP_ALL,
) -> list[Example]:
    """Examples of every record with a target for ``objective`` that ``keep`` keeps.

    Each keeps its ``max_targets`` best such targets (all, if None); ``opt_cost`` is the
    best kept target's cost.
    """
    out = []
    for rec in records:
        targets = [t for t in rec["targets"][objective] if keep.keeps(t)][:max_targets]
        if not targets:
            continue
        request = ScheduleRequest.model_validate({**rec["request"], "objective": objective})
        problem = problem_from_request(request)
        cliques = find_cliques(problem)
        out.append(
            Example(
                problem=problem,
                cliques=cliques,
                graph=graph_tensors(problem, cliques),
                targets=[
                    Assignments.single(_bits(t["a_first"]), _bits(t["following"])) for t in targets
                ],
                opt_cost=float(targets[0]["cost"]),
            )
        )
    return out


def to_data(example: Example, target: int) -> Data:
    """A PyG graph of ``example`` with target assignment ``target``.

    Attributes: x (V, NODE_DIM); edge_index (2, E); edge_attr (E, EDGE_DIM) skeleton;
    enc_attr (E, EDGE_DIM) with the target's assignment columns; conf_index (2, M);
    first_index (V,) first node of each node's robot; y_a_first, y_following (M,) float.
    """
    g = example.graph
    assignment = example.targets[target]
    first = example.problem.robot_start[example.problem.node_robot]
    return Data(
        x=g.x,
        edge_index=g.edge_index,
        edge_attr=g.edge_attr,
        enc_attr=assignment_edge_features(g, assignment),
        conf_index=g.conf.T.contiguous(),
        first_index=torch.from_numpy(first.astype(np.int64)),
        y_a_first=torch.from_numpy(assignment.a_first[0].astype(np.float32)),
        y_following=torch.from_numpy(assignment.following[0].astype(np.float32)),
        num_nodes=g.x.shape[0],
    )
