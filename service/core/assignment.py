"""Assignments: the decision for every conflict, in batches.

An assignment gives each conflict a direction (which side passes first) and a
type (exclusive or following). Solvers that sample (the GNN-VAE, CMA-ES) make
many assignments of one problem at once, so the type is a batch of S.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.core.problem import Problem

__all__ = ["Assignments"]


@dataclass(frozen=True, eq=False)
class Assignments:
    """S assignments of one problem's M conflicts.

    Shapes: a_first (S, M) bool, True where side a passes first (a -> b);
    following (S, M) bool, True where the conflict is following-type.
    """

    a_first: np.ndarray
    following: np.ndarray

    def __post_init__(self) -> None:
        if self.a_first.shape != self.following.shape or self.a_first.ndim != 2:
            raise ValueError(
                f"a_first {self.a_first.shape} and following {self.following.shape} "
                "must both be (S, M)"
            )

    @classmethod
    def single(cls, a_first: np.ndarray, following: np.ndarray) -> Assignments:
        """A batch of one from two (M,) boolean vectors."""
        return cls(
            np.asarray(a_first, dtype=bool).reshape(1, -1),
            np.asarray(following, dtype=bool).reshape(1, -1),
        )

    @property
    def n_samples(self) -> int:
        return int(self.a_first.shape[0])

    def take(self, index: int | np.ndarray) -> Assignments:
        """The sub-batch at ``index`` (an int keeps a batch of one)."""
        idx = np.atleast_1d(np.asarray(index))
        return Assignments(self.a_first[idx], self.following[idx])

    def from_to(self, problem: Problem, sample: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(M,) node indices of the first and the second node of each conflict."""
        a_first = self.a_first[sample]
        return (
            np.where(a_first, problem.conf_a, problem.conf_b),
            np.where(a_first, problem.conf_b, problem.conf_a),
        )
