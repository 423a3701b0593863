"""Re-scheduling from the fleet's progress: the residual problem from ``progress.time`` on.

A request may carry the assignment being executed (``previous``) and how far each
robot got (``progress``). The residual problem is the same graph (same nodes,
conflicts and time points, so every solver, the evaluator and the checker work
on it unchanged) with three things changed:

* **times**: robot r has passed its time points planned at or before
  ``passed_until``; those keep their planned time shifted by
  ``a_r = min(delay_r, time - p_r)`` (``p_r`` the last passed point: an estimate
  of when they were passed, never after ``time``); every other point is shifted by
  ``u_r = max(delay_r, time - T_r(first unpassed))``: the robot runs at least
  ``delay`` late and cannot reach a point before ``time``. Both shifts keep each
  robot's times strictly increasing and its delay never decreasing (a_r <= u_r).
* **settled directions**: once a robot has passed its pair enter of a conflict
  it went first: the conflict's direction is fixed (``Problem.forced``), also
  against ``previous`` (the past wins; a fixed ``first`` of the request that the
  progress contradicts is a 422).
* **realized conflicts**: both robots passed their pair enter: the decision lies
  in the past. Its direction and type are fixed (``previous``'s, else read off
  the estimated times) and its constraint, which only concerns passed points, is
  dropped (``Problem.realized``); it still counts for acyclicity and density.

Costs of the residual problem are the completion times from the shifted plan on
(absolute times, the same clock as ``progress.time``); ``avg_delay`` is measured
against the shifted plan. Points are named by their planned time
(``Problem.tp_planned``) in the dependency plan.
"""

from __future__ import annotations

import itertools
import operator
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from service.core.assignment import Assignments
from service.core.problem import (
    ErrorItem,
    Loc,
    Problem,
    ProblemError,
    forced_arcs,
    forced_cycles,
)
from service.core.schemas import PreviousConflictIn, ProgressIn

__all__ = ["Progress", "previous_from_wire", "progress_from_wire", "residual_problem"]


@dataclass(frozen=True, eq=False)
class Progress:
    """How far each robot got at ``time``. Shapes: R robots.

    ``passed_until`` is -inf for a robot that has not started.
    """

    time: float
    passed_until: np.ndarray  # (R,) float
    delay: np.ndarray  # (R,) float >= 0


def _error(loc: Loc, msg: str) -> ErrorItem:
    return ErrorItem(("body", *loc), msg)


def progress_from_wire(problem: Problem, wire: ProgressIn) -> Progress:
    """Arrays of ``wire``; unknown robots and points passed after ``time`` are a 422.

    Raises:
        ProblemError: naming ``progress.robots.<id>`` (or its ``passed_until``).
    """
    robot_index = {rid: r for r, rid in enumerate(problem.robot_ids)}
    passed = np.full(problem.n_robots, -np.inf)
    delay = np.zeros(problem.n_robots)
    errors: list[ErrorItem] = []
    for rid, rp in wire.robots.items():
        r = robot_index.get(rid)
        if r is None:
            errors.append(_error(("progress", "robots", rid), f"unknown robot id '{rid}'"))
            continue
        passed[r], delay[r] = rp.passed_until, rp.delay
        times = problem.tp_time[problem.tp_start[r] : problem.tp_start[r + 1]]  # (C_r,)
        late = times[(times > wire.time) & (times <= rp.passed_until)]
        if late.size:
            errors.append(
                _error(
                    ("progress", "robots", rid, "passed_until"),
                    f"robot '{rid}' is said to have passed its point planned at {late[0]}, "
                    f"after progress.time ({wire.time}); robots are never early",
                )
            )
    if errors:
        raise ProblemError(errors)
    return Progress(float(wire.time), passed, delay)


def previous_from_wire(problem: Problem, wire: list[PreviousConflictIn]) -> Assignments:
    """The previous answer's assignment: every conflict decided exactly once, else a 422.

    Vectorised (a 250-robot answer has ~20,000 entries): node ids are looked up
    once, each (from, to) pair is found among the conflicts by a sorted key.

    Raises:
        ProblemError: naming ``previous.<i>`` (unknown node, no such conflict, a
            conflict decided twice, a fixed direction reversed) or ``previous``
            (conflicts left undecided).
    """
    u = _column(wire, "from_", problem.node_index.get, -1, np.int64)  # (K,) node or -1
    v = _column(wire, "to", problem.node_index.get, -1, np.int64)  # (K,)
    errors = [
        _error(("previous", i, side), f"unknown node id '{getattr(wire[i], attr)}'")
        for side, attr, ends in (("from", "from_", u), ("to", "to", v))
        for i in np.flatnonzero(ends < 0)[:50].tolist()
    ]
    m = problem.conflict_between(u, v)  # (K,) conflict index or -1
    known = (u >= 0) & (v >= 0)
    errors += [
        _error(("previous", i), f"no conflict joins '{wire[i].from_}' and '{wire[i].to}'")
        for i in np.flatnonzero(known & (m < 0))[:50].tolist()
    ]
    found = np.flatnonzero(m >= 0)  # (K',) entries naming a conflict
    first_seen = np.full(problem.n_conflicts, -1, dtype=np.int64)
    first_seen[m[found[::-1]]] = found[::-1]  # the first entry of each conflict wins
    errors += [
        _error(
            ("previous", i), f"conflict {m[i]} is decided twice (also previous.{first_seen[m[i]]})"
        )
        for i in found[first_seen[m[found]] != found][:50].tolist()
    ]
    a_first = np.zeros(problem.n_conflicts, dtype=bool)
    following = np.zeros(problem.n_conflicts, dtype=bool)
    a_first[m[found]] = u[found] == problem.conf_a[m[found]]
    is_following = _column(wire, "type", operator.eq, "following", bool)  # (K,)
    following[m[found]] = is_following[found]
    reversed_ = (problem.forced != 0) & (first_seen >= 0) & (a_first != (problem.forced > 0))
    errors += [
        _error(("previous", int(first_seen[c])), f"reverses the fixed direction of conflict {c}")
        for c in np.flatnonzero(reversed_)[:50].tolist()
    ]
    undecided = np.flatnonzero(first_seen < 0)
    if undecided.size and not errors:
        errors.append(
            _error(
                ("previous",),
                f"not an assignment of this problem: {undecided.size} conflicts undecided "
                f"(first: conflict {int(undecided[0])})",
            )
        )
    if errors:
        raise ProblemError(errors[:50])
    return Assignments.single(a_first, following)


def _column(
    wire: list[PreviousConflictIn], field: str, f: Callable[[Any, Any], Any], arg: Any, dtype: type
) -> np.ndarray:
    """(K,) ``f(entry.<field>, arg)`` of every entry: the C-level map of a 20,000-entry
    ``previous`` (a Python loop per column cost twice as much)."""
    values = map(f, map(operator.attrgetter(field), wire), itertools.repeat(arg))
    return np.fromiter(values, dtype=dtype, count=len(wire))


def _shifts(problem: Problem, progress: Progress) -> tuple[np.ndarray, np.ndarray]:
    """(P,) shifted times and (P,) passed flags of every time point."""
    tp_robot = problem.tp_robot
    times = problem.tp_time  # (P,)
    passed = times <= progress.passed_until[tp_robot]  # (P,)
    n_robots = problem.n_robots
    last_passed = np.full(n_robots, -np.inf)
    np.maximum.at(last_passed, tp_robot[passed], times[passed])
    first_open = np.full(n_robots, np.inf)
    np.minimum.at(first_open, tp_robot[~passed], times[~passed])
    t, d = progress.time, progress.delay
    with np.errstate(invalid="ignore"):  # inf - inf where a robot passed all or nothing
        done_shift = np.minimum(d, t - last_passed)  # (R,)
        open_shift = np.maximum(d, t - first_open)  # (R,)
    shift = np.where(passed, done_shift[tp_robot], open_shift[tp_robot])  # (P,)
    return times + shift, passed


def residual_problem(problem: Problem, progress: Progress, previous: Assignments | None) -> Problem:
    """The problem from ``progress.time`` on (see the module docstring).

    Where the progress contradicts ``previous`` (a robot passed a conflict's entry
    that ``previous`` gave to the other robot, which has not entered it), the past
    wins: fleets report positions with some slack, and the dependency plan of the paths
    form waits at meeting places, not exactly at the graph's pair enter points. The
    direction is settled as it happened and ``previous`` is then no warm start.

    Raises:
        ProblemError: the progress contradicts a fixed direction of the request, or the
            orders it settles form a circular wait.
    """
    tp_time, tp_passed = _shifts(problem, progress)
    entered = tp_passed[problem.tp_pair_enter]  # (M, 2) side passed its pair enter
    realized = entered.all(axis=1)  # (M,)
    a_first, following = _settled(problem, tp_time, tp_passed, realized, previous)
    forced = problem.forced.copy()
    one = entered.any(axis=1) & ~realized
    settled = np.where(entered[:, 0], 1, -1).astype(np.int8)  # who entered goes first
    _check_agrees(problem, forced, one, settled)
    forced[one] = settled[one]
    forced[realized] = np.where(a_first[realized], 1, -1)
    fixed_type = np.where(realized, following.astype(np.int8), -1).astype(np.int8)
    _check_acyclic(problem, forced)
    return replace(
        problem,
        tp_time=tp_time,
        node_enter=tp_time[problem.tp_node_enter],
        node_exit=tp_time[problem.tp_node_exit],
        pair_enter=tp_time[problem.tp_pair_enter],
        pair_exit=tp_time[problem.tp_pair_exit],
        goal_time=np.where(np.isnan(problem.goal_time), np.nan, tp_time[problem.last_tp]),
        forced=forced,
        realized=realized,
        fixed_type=fixed_type,
        tp_planned=problem.tp_planned,
        tp_passed=tp_passed,
    )


def _settled(
    problem: Problem,
    tp_time: np.ndarray,
    tp_passed: np.ndarray,
    realized: np.ndarray,
    previous: Assignments | None,
) -> tuple[np.ndarray, np.ndarray]:
    """(M,) direction and type of every conflict as far as the past decides them.

    Realized conflicts take ``previous``'s decision; without it, the request's fixed
    direction or else the side whose pair enter came first (estimated times), and the
    conflict was following exactly when the second entered before the first had left.
    (A realized conflict constrains no future time, so its type only counts for density.)
    """
    if previous is not None:
        return previous.a_first[0].copy(), previous.following[0].copy()
    enter = tp_time[problem.tp_pair_enter]  # (M, 2)
    a_first = np.where(problem.forced != 0, problem.forced > 0, enter[:, 0] <= enter[:, 1])
    first = np.where(a_first, 0, 1)
    rows = np.arange(problem.n_conflicts)
    first_left = tp_passed[problem.tp_pair_exit[rows, first]] & (
        tp_time[problem.tp_pair_exit[rows, first]] <= enter[rows, 1 - first]
    )
    return a_first, ~first_left


def _check_agrees(
    problem: Problem, forced: np.ndarray, one: np.ndarray, settled: np.ndarray
) -> None:
    """Where one robot entered first, a fixed direction of the request must say so too."""
    bad = one & (forced != 0) & (forced != settled)
    if bad.any():
        errors = [
            _contradiction(problem, m, 0 if settled[m] > 0 else 1)
            for m in np.flatnonzero(bad)[:50].tolist()
        ]
        raise ProblemError(errors)


def _contradiction(problem: Problem, m: int, side: int) -> ErrorItem:
    """The error naming the robot that passed a conflict's entry out of turn."""
    nodes = (problem.conf_a[m], problem.conf_b[m])
    robot = problem.robot_ids[problem.node_robot[nodes[side]]]
    other = problem.robot_ids[problem.node_robot[nodes[1 - side]]]
    return _error(
        ("progress", "robots", robot, "passed_until"),
        f"robot '{robot}' passed the entry of conflict {m} ('{problem.node_ids[nodes[side]]}') "
        f"before robot '{other}' entered it, against the conflict's fixed first",
    )


def _check_acyclic(problem: Problem, forced: np.ndarray) -> None:
    """Directions settled by the past cannot form a circular wait unless progress is wrong."""
    cycles = forced_cycles(problem.node_robot, *forced_arcs(problem.conf_a, problem.conf_b, forced))
    if cycles:
        raise ProblemError(
            [
                _error(
                    ("progress",),
                    f"the orders this progress settles form a circular wait: conflicts {c}",
                )
                for c in cycles[:50]
            ]
        )
