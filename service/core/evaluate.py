"""The one evaluator: least updated times and all four costs, for many assignments at once.

Updated times T~ are the least values with T~(1) >= T(1), a robot's delay
D = T~ - T never decreasing along its path, and T~_to(pair_enter) >= T~_from(pair_exit)
(exclusive) or >= T~_from(pair_enter) (following) for every conflict. That is a
longest path on a DAG. Delays only rise at *events*: the distinct pair-enter
time points of each robot (the only targets of conflict constraints). So the
evaluator keeps one delay per event, laid out per robot as a padded (R, K)
block, and relaxes all conflicts of all S assignments in vectorized sweeps:
each sweep propagates one more conflict along every longest path, so it
converges in (longest chain of conflicts + 1) sweeps. Published GNN-VAE
inference was bottlenecked by evaluating its 100 samples; this is why the
layout is batched and sweep-based instead of a per-sample topological sort.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.core.assignment import Assignments
from service.core.problem import Problem
from service.core.schemas import OBJECTIVES, Objective

__all__ = ["Evaluation", "Evaluator", "costs_from_completion"]


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Least updated times of S assignments.

    Shapes: delay_slots (S, R*K+1) delay of every event slot (last column is the
    zero slot of time points before any event); completion (S, R);
    costs[objective] (S,); converged (S,) bool, False only for cyclic assignments
    (their costs are +inf).
    """

    delay_slots: np.ndarray
    completion: np.ndarray
    costs: dict[Objective, np.ndarray]
    converged: np.ndarray


def costs_from_completion(completion: np.ndarray) -> dict[str, np.ndarray]:
    """avg, max and sync completion from (S, R) completion times -> (S,) each."""
    avg = completion.mean(axis=1)
    return {
        "avg_completion": avg,
        "max_completion": completion.max(axis=1),
        "sync_completion": avg + np.abs(completion - avg[:, None]).mean(axis=1),
    }


class Evaluator:
    """Evaluates batches of assignments of one problem; build once, call many times."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        n_robots = problem.n_robots
        tp_robot = problem.tp_robot
        # Events: distinct pair-enter time points, already sorted by (robot, time).
        events = np.unique(problem.tp_pair_enter.ravel())  # (E,)
        ev_robot = tp_robot[events]
        ev_rank = np.arange(events.size) - np.searchsorted(ev_robot, ev_robot, side="left")
        self.width = int(ev_rank.max() + 1) if events.size else 1  # K
        self.zero_slot = n_robots * self.width
        ev_slot = ev_robot * self.width + ev_rank  # (E,)
        self._tp_slot = self._slot_of_time_points(problem, events, ev_slot)  # (P,)
        self._build_relaxation(problem)
        counts = np.diff(problem.tp_start).astype(np.float64)  # (R,) time points per robot
        weights = np.zeros(self.zero_slot + 1)
        np.add.at(weights, self._tp_slot, 1.0 / (counts[tp_robot] * n_robots))
        self._delay_weight = weights  # (R*K+1,) avg_delay = delay_slots @ weights
        self._last_slot = self._tp_slot[problem.last_tp]  # (R,)
        self._free = problem.free_time()  # (R,)

    def _slot_of_time_points(self, problem: Problem, events: np.ndarray, ev_slot: np.ndarray) -> np.ndarray:
        """(P,) slot of the last event at or before each time point (zero slot if none)."""
        tp_robot = problem.tp_robot
        if events.size == 0:
            return np.full(tp_robot.size, self.zero_slot, dtype=np.int64)
        pos = np.searchsorted(events, np.arange(tp_robot.size), side="right") - 1  # (P,)
        last = np.maximum(pos, 0)
        same_robot = (pos >= 0) & (tp_robot[events[last]] == tp_robot)
        return np.where(same_robot, ev_slot[last], self.zero_slot)

    def _build_relaxation(self, problem: Problem) -> None:
        """Fixed index structure of the 2M conflict constraints, sorted by target slot.

        Slot (c, s) constrains side s of conflict c (the one that passes second)
        by side 1-s; it is active when side 1-s passes first.
        """
        tp_slot = self._tp_slot
        pe, px, t = problem.tp_pair_enter, problem.tp_pair_exit, problem.tp_time
        other = pe[:, ::-1], px[:, ::-1]  # (M, 2) time points of the side passing first
        target = tp_slot[pe].ravel()  # (2M,)
        order = np.argsort(target, kind="stable")
        self._order = order
        self._src_excl = tp_slot[other[1]].ravel()[order]
        self._src_foll = tp_slot[other[0]].ravel()[order]
        self._off_excl = (t[other[1]] - t[pe]).ravel()[order]
        self._off_foll = (t[other[0]] - t[pe]).ravel()[order]
        sorted_target = target[order]
        self._targets, self._seg = np.unique(sorted_target, return_index=True)

    def evaluate(self, assignments: Assignments) -> Evaluation:
        """Least updated times and costs of every assignment in the batch."""
        problem = self.problem
        n_samples = assignments.n_samples
        n_robots, width = problem.n_robots, self.width
        # Slot (c, 0) is active when b passes first, slot (c, 1) when a does.
        active = np.stack([~assignments.a_first, assignments.a_first], axis=2)
        active = active.reshape(n_samples, -1)[:, self._order]  # (S, 2M)
        following = np.repeat(assignments.following, 2, axis=1)[:, self._order]  # (S, 2M)
        src = np.where(following, self._src_foll, self._src_excl)  # (S, 2M)
        off = np.where(following, self._off_foll, self._off_excl)  # (S, 2M)
        slots = np.zeros((n_samples, n_robots * width + 1))  # (S, R*K+1)
        converged = np.ones(n_samples, dtype=bool)
        if src.shape[1]:
            converged = self._relax(slots, src, off, active)
        completion = problem.tp_time[problem.last_tp] + slots[:, self._last_slot]  # (S, R)
        costs = costs_from_completion(completion)
        costs["avg_delay"] = slots @ self._delay_weight
        costs = {k: np.where(converged, costs[k], np.inf) for k in OBJECTIVES}
        return Evaluation(slots, completion, costs, converged)

    def _relax(
        self, slots: np.ndarray, src: np.ndarray, off: np.ndarray, active: np.ndarray
    ) -> np.ndarray:
        """Sweep conflict constraints until no delay changes; updates ``slots`` in place.

        Returns (S,) bool: converged within M+1 sweeps (always, for acyclic input).
        """
        for _ in range(src.shape[1] // 2 + 1):
            new = self._sweep(slots, src, off, active)
            if np.array_equal(new, slots[:, :-1]):
                return np.ones(slots.shape[0], dtype=bool)
            slots[:, :-1] = new
        return np.all(self._sweep(slots, src, off, active) == slots[:, :-1], axis=1)

    def _sweep(
        self, slots: np.ndarray, src: np.ndarray, off: np.ndarray, active: np.ndarray
    ) -> np.ndarray:
        """One Jacobi relaxation of every conflict, then the running max along each robot.

        Shapes: slots (S, R*K+1); src, off, active (S, 2M) -> (S, R*K).
        """
        n_samples = slots.shape[0]
        rows = np.arange(n_samples)[:, None]
        value = np.where(active, slots[rows, src] + off, 0.0)  # (S, 2M)
        incoming = np.zeros((n_samples, slots.shape[1] - 1))  # (S, R*K)
        incoming[:, self._targets] = np.maximum.reduceat(value, self._seg, axis=1).clip(min=0.0)
        body = incoming.reshape(n_samples, self.problem.n_robots, self.width)
        return np.maximum.accumulate(body, axis=2).reshape(n_samples, -1)

    def delays_at(self, evaluation: Evaluation, sample: int, time_points: np.ndarray) -> np.ndarray:
        """Delays D at the given time points of one evaluated sample (same shape)."""
        return evaluation.delay_slots[sample, self._tp_slot[time_points]]

    def free_costs(self) -> dict[str, float]:
        """Every objective's cost with zero delay (each robot at its expected last time point)."""
        zero = costs_from_completion(self._free[None, :])
        zero["avg_delay"] = np.zeros(1)
        return {k: float(v[0]) for k, v in zero.items()}
