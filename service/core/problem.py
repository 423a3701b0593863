"""The validated problem model: a coordination skeleton graph in numpy arrays.

A :class:`Problem` is built once per request from a :class:`ScheduleRequest`
by :func:`problem_from_request`, which enforces every cross-field input rule
of the contract and reports each violation with the location of the field at
fault. Everything downstream (evaluator, decoder, checker, solvers) reads only
these arrays, never the wire model.

Indexing: robots ``0..R-1`` in request order; nodes ``0..V-1`` grouped by robot
and in path order (``robot_start[r] <= v < robot_start[r+1]``); conflicts
``0..M-1`` in request order with sides ``a`` and ``b``; time points ``0..P-1``
grouped by robot, sorted within each robot (``tp_start[r] <= t < tp_start[r+1]``).

Fixed directions (a conflict's ``first``) are kept in ``forced``; they must not
form a circular wait with the robots' path order, else the request is rejected.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from itertools import chain, repeat
from operator import itemgetter
from typing import Any, NamedTuple

import numpy as np

from service.core.digraph import components
from service.core.lazy import cached_property
from service.core.schemas import ConflictIn, ScheduleRequest

__all__ = [
    "DensityLimit",
    "ErrorItem",
    "Problem",
    "ProblemError",
    "forced_arcs",
    "forced_cycles",
    "problem_from_arrays",
    "problem_from_request",
]

Loc = tuple[str | int, ...]
# How many input violations one error response lists at most.
MAX_REPORTED_ERRORS = 50


@dataclass(frozen=True)
class ErrorItem:
    """One input violation: where it is (FastAPI-style ``loc``) and what is wrong."""

    loc: Loc
    msg: str
    type: str = "value_error"

    def as_dict(self) -> dict[str, Any]:
        """Render like a FastAPI validation error entry."""
        return {"loc": list(self.loc), "msg": self.msg, "type": self.type}


class ProblemError(ValueError):
    """The request is well-typed but breaks a rule of the contract."""

    def __init__(self, errors: Sequence[ErrorItem]) -> None:
        self.errors = list(errors)
        super().__init__("; ".join(f"{'.'.join(map(str, e.loc))}: {e.msg}" for e in self.errors))


class DensityLimit(NamedTuple):
    """An explicit density clique: node indices and the robots allowed in it at once (one
    limit of :class:`DensityLimits`, as iterating them gives it)."""

    nodes: np.ndarray  # (k,) int, sorted node indices
    max_robots: int


@dataclass(frozen=True, eq=False)
class DensityLimits:
    """The explicit density cliques in CSR layout: limit k's node indices, sorted, are
    ``nodes[start[k]:start[k + 1]]``, with at most ``max_robots[k]`` robots in them at once.

    Arrays, not an object per limit: paths of 250 robots give ~11,600 limits, and a named
    tuple each took ~25 ms of a request to build (session 60). Indexing and iterating give
    limits as :class:`DensityLimit` (for tests and messages, not for work per limit).

    Shapes: L limits, K node entries.
    """

    nodes: np.ndarray  # (K,) int
    start: np.ndarray  # (L+1,) int
    max_robots: np.ndarray  # (L,) int

    @classmethod
    def empty(cls) -> DensityLimits:
        """No limit."""
        return cls(np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(0, np.int64))

    @classmethod
    def of_pairs(cls, pairs: np.ndarray, max_robots: int) -> DensityLimits:
        """A limit of ``max_robots`` on each node pair of ``pairs`` (L, 2) int."""
        pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)  # (L, 2)
        count = pairs.shape[0]
        return cls(
            pairs.ravel(),
            np.arange(0, 2 * count + 1, 2, dtype=np.int64),
            np.full(count, max_robots, dtype=np.int64),
        )

    def __len__(self) -> int:
        return int(self.max_robots.size)

    def __getitem__(self, k: int) -> DensityLimit:
        return DensityLimit(self.nodes[self.start[k] : self.start[k + 1]], int(self.max_robots[k]))

    def __iter__(self) -> Iterator[DensityLimit]:
        return (self[k] for k in range(len(self)))

    def take(self, keep: np.ndarray, renumber: np.ndarray) -> DensityLimits:
        """The limits in mask ``keep`` (L,) with node v renumbered ``renumber[v]`` (V,; a
        sub-problem's numbering, increasing over the nodes kept, so nodes stay sorted)."""
        sizes = np.diff(self.start)  # (L,)
        entries = np.repeat(keep, sizes)  # (K,)
        return DensityLimits(
            renumber[self.nodes[entries]],
            np.concatenate([[0], np.cumsum(sizes[keep])]).astype(np.int64),
            self.max_robots[keep],
        )


def forced_arcs(
    conf_a: np.ndarray, conf_b: np.ndarray, forced: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixed conflicts (F,) and their first (F,) and second (F,) nodes, from forced (M,) int8."""
    conflicts = np.flatnonzero(forced)
    a_first = forced[conflicts] > 0
    a, b = conf_a[conflicts], conf_b[conflicts]
    return conflicts, np.where(a_first, a, b), np.where(a_first, b, a)


@dataclass(frozen=True, eq=False)
class _PairIndex:
    """Conflicts by node pair: sorted (M,) keys min*N + max of every conflict's nodes, and
    (M,) the conflict of each key."""

    keys: np.ndarray
    order: np.ndarray
    n_nodes: int

    @classmethod
    def of(cls, conf_a: np.ndarray, conf_b: np.ndarray, n_nodes: int) -> _PairIndex:
        a, b = conf_a.astype(np.int64), conf_b.astype(np.int64)
        keys = np.minimum(a, b) * n_nodes + np.maximum(a, b)  # (M,) unique per pair
        order = np.argsort(keys)
        return cls(keys[order], order, n_nodes)

    def find(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The conflict joining nodes ``u`` and ``v`` (same shape) in either order, or -1
        (also where a node is -1)."""
        if self.keys.size == 0:
            return np.full(np.shape(u), -1, dtype=np.int64)
        wanted = np.minimum(u, v) * self.n_nodes + np.maximum(u, v)  # like u
        pos = np.minimum(np.searchsorted(self.keys, wanted), self.keys.size - 1)  # like u
        hit = (u >= 0) & (v >= 0) & (self.keys[pos] == wanted)
        return np.where(hit, self.order[pos], -1)


@dataclass(frozen=True, eq=False)
class Problem:
    """A validated coordination skeleton graph.

    Shapes: R robots, V nodes, M conflicts, P time points.
    """

    robot_ids: tuple[str, ...]
    node_ids: tuple[str, ...]
    robot_start: np.ndarray  # (R+1,) int, nodes of robot r are robot_start[r]:robot_start[r+1]
    node_robot: np.ndarray  # (V,) int
    node_enter: np.ndarray  # (V,) float
    node_exit: np.ndarray  # (V,) float
    node_density: np.ndarray  # (V,) int >= 1
    goal_time: np.ndarray  # (R,) float, NaN where not given
    conf_a: np.ndarray  # (M,) int node index of side a
    conf_b: np.ndarray  # (M,) int node index of side b
    pair_enter: np.ndarray  # (M, 2) float, column 0 side a, column 1 side b
    pair_exit: np.ndarray  # (M, 2) float
    forced: np.ndarray  # (M,) int8, +1 side a passes first, -1 side b first, 0 free
    density_limits: DensityLimits
    tp_time: np.ndarray  # (P,) float, sorted within each robot
    tp_start: np.ndarray  # (R+1,) int
    tp_pair_enter: np.ndarray  # (M, 2) int time point of each side's pair enter
    tp_pair_exit: np.ndarray  # (M, 2) int
    tp_node_enter: np.ndarray  # (V,) int
    tp_node_exit: np.ndarray  # (V,) int
    node_index: dict[str, int] = field(repr=False)
    # Re-scheduling (service.core.progress): all-free / all-unpassed for a fresh problem.
    realized: np.ndarray  # (M,) bool, decided in the past: no constraint on future times
    fixed_type: np.ndarray  # (M,) int8, -1 free, 0 exclusive, 1 following (realized ones)
    tp_planned: np.ndarray  # (P,) float, the request's own time of each point (names it)
    tp_passed: np.ndarray  # (P,) bool, passed before the re-schedule's time

    @property
    def n_robots(self) -> int:
        return len(self.robot_ids)

    @property
    def n_nodes(self) -> int:
        return len(self.node_ids)

    @property
    def n_conflicts(self) -> int:
        return int(self.conf_a.shape[0])

    @property
    def conf_nodes(self) -> np.ndarray:
        """(M, 2) int: node index of side a and side b of every conflict."""
        return np.stack([self.conf_a, self.conf_b], axis=1)

    @cached_property
    def forced_arcs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The fixed directions: conflicts (F,) int, their first (F,) and second (F,) nodes."""
        return forced_arcs(self.conf_a, self.conf_b, self.forced)

    @cached_property
    def has_forced(self) -> bool:
        """Whether any conflict's direction is fixed (solvers skip all extra work if not)."""
        return bool(self.forced.any())

    @cached_property
    def _pairs(self) -> _PairIndex:
        return _PairIndex.of(self.conf_a, self.conf_b, self.n_nodes)

    def conflict_between(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The conflict joining nodes ``u`` and ``v`` (same shape, any) in either order,
        or -1 (also where a node is -1)."""
        return self._pairs.find(u, v)

    @cached_property
    def tp_robot(self) -> np.ndarray:
        """(P,) int: the robot each time point belongs to."""
        return np.repeat(np.arange(self.n_robots), np.diff(self.tp_start))

    @property
    def last_tp(self) -> np.ndarray:
        """(R,) int: each robot's last (completion) time point."""
        return self.tp_start[1:] - 1

    @cached_property
    def events(self) -> np.ndarray:
        """(E,) int: distinct pair-enter time points, sorted by (robot, time).

        Delays only rise at events (the only targets of conflict constraints), so
        the evaluator and the exact solver keep one delay per event.
        """
        return np.unique(self.tp_pair_enter.ravel())

    @cached_property
    def tp_event(self) -> np.ndarray:
        """(P,) int: the last event at or before each time point of its robot (E if none)."""
        events, tp_robot = self.events, self.tp_robot
        if events.size == 0:
            return np.zeros(tp_robot.size, dtype=np.int64)
        pos = np.searchsorted(events, np.arange(tp_robot.size), side="right") - 1  # (P,)
        last = np.maximum(pos, 0)
        same_robot = (pos >= 0) & (tp_robot[events[last]] == tp_robot)
        return np.where(same_robot, last, events.size).astype(np.int64)

    @cached_property
    def event_robot(self) -> np.ndarray:
        """(E,) int: each event's robot, non-decreasing (a robot's events are contiguous)."""
        return self.tp_robot[self.events]

    @cached_property
    def event_next(self) -> np.ndarray:
        """(E,) int: the next event of the same robot, or -1."""
        ev_robot = self.event_robot
        same_next = np.zeros(ev_robot.size, dtype=bool)
        same_next[:-1] = ev_robot[1:] == ev_robot[:-1]
        return np.where(same_next, np.arange(1, ev_robot.size + 1), -1)

    def free_time(self) -> np.ndarray:
        """(R,) float: each robot's completion time with zero delay."""
        return self.tp_time[self.last_tp]


class _Collector:
    """Accumulates input violations and raises them together."""

    def __init__(self) -> None:
        self.errors: list[ErrorItem] = []

    def add(self, loc: Loc, msg: str) -> None:
        if len(self.errors) < MAX_REPORTED_ERRORS:
            self.errors.append(ErrorItem(("body", *loc), msg))

    def raise_if_any(self) -> None:
        if self.errors:
            raise ProblemError(self.errors)


def problem_from_request(req: ScheduleRequest) -> Problem:
    """Validate the cross-field rules of ``req`` and build its :class:`Problem`.

    Raises:
        ProblemError: listing every violated rule with the location at fault.
    """
    errs = _Collector()
    node_index, node_robot, node_pos_loc = _index_nodes(req, errs)
    errs.raise_if_any()
    _check_node_times(req, errs)
    conf_a, conf_b, pair_enter, pair_exit = _conflicts(req, node_index, node_robot, errs)
    errs.raise_if_any()
    limits = _density_limits(req, node_index, conf_a, conf_b, errs)
    _check_goal_times(req, node_robot, conf_a, conf_b, pair_enter, pair_exit, errs)
    forced = _forced(req)
    if forced.any():
        _check_forced_acyclic(req, node_robot, *forced_arcs(conf_a, conf_b, forced), errs)
    errs.raise_if_any()
    return _build(
        req, node_index, node_robot, conf_a, conf_b, pair_enter, pair_exit, forced, limits
    )


def _index_nodes(
    req: ScheduleRequest, errs: _Collector
) -> tuple[dict[str, int], np.ndarray, list[Loc]]:
    """Give every node an index; report duplicate robot or node ids."""
    robot_seen: dict[str, int] = {}
    node_index: dict[str, int] = {}
    node_robot: list[int] = []
    locs: list[Loc] = []
    for i, robot in enumerate(req.robots):
        if robot.id in robot_seen:
            errs.add(("robots", i, "id"), f"duplicate robot id '{robot.id}'")
        robot_seen.setdefault(robot.id, i)
        for j, node in enumerate(robot.nodes):
            if node.id in node_index:
                errs.add(("robots", i, "nodes", j, "id"), f"duplicate node id '{node.id}'")
                continue
            node_index[node.id] = len(node_robot)
            node_robot.append(i)
            locs.append(("robots", i, "nodes", j))
    return node_index, np.asarray(node_robot, dtype=np.int64), locs


def _check_node_times(req: ScheduleRequest, errs: _Collector) -> None:
    """enter < exit on every node; a robot's nodes strictly separated in path order."""
    for i, robot in enumerate(req.robots):
        for j, node in enumerate(robot.nodes):
            if not node.exit > node.enter:
                errs.add(
                    ("robots", i, "nodes", j, "exit"),
                    f"node '{node.id}': exit ({node.exit}) must be greater than "
                    f"enter ({node.enter})",
                )
            if j > 0 and not node.enter > robot.nodes[j - 1].exit:
                prev = robot.nodes[j - 1]
                errs.add(
                    ("robots", i, "nodes", j, "enter"),
                    f"node '{node.id}' must enter ({node.enter}) after node '{prev.id}' exits "
                    f"({prev.exit}): nodes are listed in path order and may not overlap or touch",
                )


def _conflicts(
    req: ScheduleRequest, node_index: dict[str, int], node_robot: np.ndarray, errs: _Collector
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Resolve conflict endpoints and pair times; report every rule they break.

    A valid request (every service-made one) is read in bulk (:func:`_valid_conflicts`:
    0.15 -> 0.03 s at 23,000 conflicts); only a faulty one is walked conflict by
    conflict, which names every fault.
    """
    valid = _valid_conflicts(req, node_index, node_robot)
    if valid is not None:
        return valid
    nodes = {n.id: n for r in req.robots for n in r.nodes}
    conf_a: list[int] = []
    conf_b: list[int] = []
    enters: list[tuple[float, float]] = []
    exits: list[tuple[float, float]] = []
    pairs: dict[frozenset[int], int] = {}
    for k, c in enumerate(req.conflicts):
        missing = [s for s in ("a", "b") if c[s] not in node_index]
        for s in missing:
            errs.add(("conflicts", k, s), f"unknown node id '{c[s]}'")
        if missing:
            continue
        a, b = node_index[c["a"]], node_index[c["b"]]
        if node_robot[a] == node_robot[b]:
            errs.add(
                ("conflicts", k),
                f"conflict joins '{c['a']}' and '{c['b']}' of the same robot "
                f"'{req.robots[node_robot[a]].id}'",
            )
            continue
        key = frozenset((a, b))
        if key in pairs:
            errs.add(
                ("conflicts", k),
                f"duplicate conflict between '{c['a']}' and '{c['b']}' "
                f"(also conflict {pairs[key]})",
            )
            continue
        pairs[key] = k
        side_times = []
        for side, nid in (("a", c["a"]), ("b", c["b"])):
            node = nodes[nid]
            enter = c.get(f"{side}_enter")
            exit_ = c.get(f"{side}_exit")
            enter = node.enter if enter is None else enter
            exit_ = node.exit if exit_ is None else exit_
            for name, value in ((f"{side}_enter", enter), (f"{side}_exit", exit_)):
                if not node.enter <= value <= node.exit:
                    errs.add(
                        ("conflicts", k, name),
                        f"{name} ({value}) must lie inside node '{nid}' "
                        f"[{node.enter}, {node.exit}]",
                    )
            if not exit_ > enter:
                errs.add(
                    ("conflicts", k, f"{side}_exit"),
                    f"{side}_exit ({exit_}) must be greater than {side}_enter ({enter})",
                )
            side_times.append((enter, exit_))
        conf_a.append(a)
        conf_b.append(b)
        enters.append((side_times[0][0], side_times[1][0]))
        exits.append((side_times[0][1], side_times[1][1]))
    return (
        np.asarray(conf_a, dtype=np.int64),
        np.asarray(conf_b, dtype=np.int64),
        np.asarray(enters, dtype=np.float64).reshape(-1, 2),
        np.asarray(exits, dtype=np.float64).reshape(-1, 2),
    )


def _valid_conflicts(
    req: ScheduleRequest, node_index: dict[str, int], node_robot: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`_conflicts`'s arrays when every conflict keeps every rule, else None.

    The same rules, in bulk: known endpoints of two robots, no pair twice, pair times
    (a missing one is its node's) inside their nodes and exits after enters.
    Shapes: M conflicts -> a, b (M,) node indices, enters, exits (M, 2) [side a, side b].
    """
    conflicts, m = req.conflicts, len(req.conflicts)
    ends = chain(map(itemgetter("a"), conflicts), map(itemgetter("b"), conflicts))
    try:  # fields read by map: 28 -> 20 ms at 21,835 conflicts (session 60, as attributes)
        a, b = np.fromiter(map(node_index.__getitem__, ends), np.int64, 2 * m).reshape(2, m)
    except KeyError:
        return None
    lo = np.array([n.enter for r in req.robots for n in r.nodes], dtype=np.float64)  # (V,)
    hi = np.array([n.exit for r in req.robots for n in r.nodes], dtype=np.float64)
    given = _given_times(conflicts)  # (M, 4) a_enter b_enter a_exit b_exit, NaN: the node's
    node_lo = np.stack([lo[a], lo[b]], axis=1)  # (M, 2)
    node_hi = np.stack([hi[a], hi[b]], axis=1)
    enters = np.where(np.isnan(given[:, :2]), node_lo, given[:, :2])  # (M, 2)
    exits = np.where(np.isnan(given[:, 2:]), node_hi, given[:, 2:])
    keys = np.minimum(a, b) * max(lo.size, 1) + np.maximum(a, b)  # (M,) the unordered pair
    ok = (
        np.all(node_robot[a] != node_robot[b])
        and np.unique(keys).size == keys.size
        and np.all((node_lo <= enters) & (enters <= node_hi))
        and np.all((node_lo <= exits) & (exits <= node_hi))
        and np.all(exits > enters)
    )
    return (a.copy(), b.copy(), enters, exits) if ok else None


def _given_times(conflicts: list[ConflictIn]) -> np.ndarray:
    """(M, 4) each conflict's a_enter, b_enter, a_exit, b_exit as given; NaN where absent
    or None (the node's time). One tuple per conflict where every conflict gives all four
    (derived graphs do): 9 ms at 21,835 conflicts, 11 ms by key with a default."""
    fields = ("a_enter", "b_enter", "a_exit", "b_exit")
    try:
        rows = list(map(itemgetter(*fields), conflicts))
    except KeyError:
        rows = [tuple(c.get(f) for f in fields) for c in conflicts]
    return np.array(rows, dtype=np.float64).reshape(-1, 4)


def _density_limits(
    req: ScheduleRequest,
    node_index: dict[str, int],
    conf_a: np.ndarray,
    conf_b: np.ndarray,
    errs: _Collector,
) -> DensityLimits:
    """Resolve explicit density cliques; their nodes must be pairwise in conflict.

    In bulk: every limit's nodes are looked up in one pass and checked as one array
    (sorted within each limit), their pairs limits of one size at a time; only limits
    found faulty are walked one by one for their messages. Paths of 250 robots send ~11,600
    limits (pairs that may not be occupied at once): 75 ms one limit at a time, ~20 ms
    here with an object per limit kept, ~10 ms with the kept limits as arrays (session 60).
    Errors are reported in the order of the limits.
    """
    lims = req.density_limits
    names = list(map(itemgetter("nodes"), lims))  # (L,) lists of node ids
    sizes = np.fromiter(map(len, names), np.int64, len(lims))  # (L,)
    ids = chain.from_iterable(names)
    flat = np.fromiter(map(node_index.get, ids, repeat(-1)), np.int64, int(sizes.sum()))
    # (K,) node index, -1 unknown
    owner = np.repeat(np.arange(len(lims)), sizes)  # (K,)
    order = np.lexsort((flat, owner))
    nodes, owner = flat[order], owner[order]  # sorted within each limit
    faulty = np.zeros(len(lims), dtype=bool)  # (L,)
    faulty[owner[nodes < 0]] = True
    faulty[owner[1:][(nodes[1:] == nodes[:-1]) & (owner[1:] == owner[:-1])]] = True
    messages = {int(k): _limit_faults(names[k], node_index) for k in np.flatnonzero(faulty)}
    starts = np.concatenate([[0], np.cumsum(sizes)])  # (L+1,)
    pairs = _PairIndex.of(conf_a, conf_b, len(node_index))
    for size in np.unique(sizes[~faulty]).tolist():
        which = np.flatnonzero(~faulty & (sizes == size))  # (L_s,)
        given = flat[starts[which][:, None] + np.arange(size)]  # (L_s, size) in given order
        i, j = np.triu_indices(size, 1)  # every pair, in the order of the limit's nodes
        missing = pairs.find(given[:, i], given[:, j]) < 0  # (L_s, pairs)
        for row in np.flatnonzero(missing.any(axis=1)).tolist():
            k, p = int(which[row]), int(np.argmax(missing[row]))
            given_names = names[k]
            messages[k] = [
                "nodes are not a clique of the conflict graph: "
                f"no conflict between '{given_names[i[p]]}' and '{given_names[j[p]]}'"
            ]
    for k in sorted(messages):
        for msg in messages[k]:
            errs.add(("density_limits", k, "nodes"), msg)
    keep = np.ones(len(lims), dtype=bool)  # (L,)
    keep[list(messages)] = False
    most = np.fromiter(map(itemgetter("max_robots"), lims), np.int64, len(lims))  # (L,)
    return DensityLimits(
        nodes[keep[owner]],
        np.concatenate([[0], np.cumsum(sizes[keep])]).astype(np.int64),
        most[keep],
    )


def _limit_faults(names: list[str], node_index: dict[str, int]) -> list[str]:
    """The messages of a limit naming an unknown node or one node twice."""
    found = [f"unknown node id '{n}'" for n in names if n not in node_index]
    if len(set(names)) != len(names):
        found.append("a node is listed twice")
    return found


def _check_goal_times(
    req: ScheduleRequest,
    node_robot: np.ndarray,
    conf_a: np.ndarray,
    conf_b: np.ndarray,
    pair_enter: np.ndarray,
    pair_exit: np.ndarray,
    errs: _Collector,
) -> None:
    """A goal time may not precede any other time point of its robot."""
    latest = np.array([r.nodes[-1].exit for r in req.robots], dtype=np.float64)
    for side, nodes in ((0, conf_a), (1, conf_b)):
        if nodes.size:
            np.maximum.at(latest, node_robot[nodes], pair_exit[:, side])
    for i, robot in enumerate(req.robots):
        if robot.goal_time is not None and robot.goal_time < latest[i]:
            errs.add(
                ("robots", i, "goal_time"),
                f"goal_time ({robot.goal_time}) of robot '{robot.id}' precedes its last "
                f"time point ({latest[i]})",
            )


def _forced(req: ScheduleRequest) -> np.ndarray:
    """(M,) int8 fixed directions: +1 where side a must pass first, -1 side b, 0 free."""
    sign = {"a": 1, "b": -1, None: 0}
    return np.array([sign[c.get("first")] for c in req.conflicts], dtype=np.int8)


def forced_cycles(
    node_robot: np.ndarray, conflicts: np.ndarray, first: np.ndarray, second: np.ndarray
) -> list[list[int]]:
    """Fixed arcs first -> second (F,) of ``conflicts`` that close a circular wait with path
    order: one list of conflict indices per cycle (empty when the arcs leave a DAG).

    Only the F fixed arcs' endpoints matter: between two of them a cycle can only
    follow a robot's path forward, so the graph is those endpoints, chained in
    path order per robot (node indices increase along paths), plus the fixed
    arcs. A fixed arc lies on a cycle exactly when both ends share a strongly
    connected component.
    """
    if conflicts.size == 0:
        return []
    ends = np.unique(np.concatenate([first, second]))  # (U,) sorted node indices
    same = node_robot[ends[1:]] == node_robot[ends[:-1]]
    chain = np.flatnonzero(same)  # path arcs ends[k] -> ends[k+1], as positions in ends
    first_at, second_at = np.searchsorted(ends, first), np.searchsorted(ends, second)
    _, label = components(ends.size, chain, chain + 1, first_at, second_at)
    on_cycle = label[first_at] == label[second_at]  # (F,)
    return [
        conflicts[on_cycle & (label[first_at] == c)].tolist()
        for c in np.unique(label[first_at][on_cycle])
    ]


def _check_forced_acyclic(
    req: ScheduleRequest,
    node_robot: np.ndarray,
    conflicts: np.ndarray,
    first: np.ndarray,
    second: np.ndarray,
    errs: _Collector,
) -> None:
    """Fixed directions plus path order must leave a DAG; name every fixed arc on a cycle."""
    for cycle in forced_cycles(node_robot, conflicts, first, second):
        for k in cycle:
            c = req.conflicts[k]
            errs.add(
                ("conflicts", k, "first"),
                f"fixed directions form a circular wait with the robots' path order: conflicts "
                f"{cycle} (this one: '{c['a']}' and '{c['b']}', first '{c['first']}')",
            )


def _build(
    req: ScheduleRequest,
    node_index: dict[str, int],
    node_robot: np.ndarray,
    conf_a: np.ndarray,
    conf_b: np.ndarray,
    pair_enter: np.ndarray,
    pair_exit: np.ndarray,
    forced: np.ndarray,
    limits: DensityLimits,
) -> Problem:
    """The :class:`Problem` of a request whose rules were checked."""
    nodes = [n for r in req.robots for n in r.nodes]
    return problem_from_arrays(
        robot_ids=tuple(r.id for r in req.robots),
        node_ids=tuple(n.id for n in nodes),
        node_robot=node_robot,
        node_enter=np.array([n.enter for n in nodes], dtype=np.float64),
        node_exit=np.array([n.exit for n in nodes], dtype=np.float64),
        node_density=np.array([n.density for n in nodes], dtype=np.int64),
        goal_time=np.array(
            [np.nan if r.goal_time is None else r.goal_time for r in req.robots], dtype=np.float64
        ),
        conf_a=conf_a,
        conf_b=conf_b,
        pair_enter=pair_enter,
        pair_exit=pair_exit,
        forced=forced,
        density_limits=limits,
        node_index=node_index,
    )


def problem_from_arrays(
    *,
    robot_ids: tuple[str, ...],
    node_ids: tuple[str, ...],
    node_robot: np.ndarray,
    node_enter: np.ndarray,
    node_exit: np.ndarray,
    node_density: np.ndarray,
    goal_time: np.ndarray,
    conf_a: np.ndarray,
    conf_b: np.ndarray,
    pair_enter: np.ndarray,
    pair_exit: np.ndarray,
    forced: np.ndarray,
    density_limits: DensityLimits | None = None,
    node_index: dict[str, int] | None = None,
) -> Problem:
    """Assemble a :class:`Problem` from arrays that already obey the contract's rules,
    adding each robot's sorted distinct time points.

    Nothing is checked here: :func:`problem_from_request` checks a request first; a graph
    derived from paths (``service.geometry``) obeys the rules by construction and skips
    building, validating and reading back a graph-form request (0.14 s at 23,000
    conflicts). Shapes as in :class:`Problem` (nodes grouped by robot, in path order).
    """
    n_robots, n_nodes, n_pairs = len(robot_ids), node_robot.size, 2 * conf_a.size
    conf_robot = node_robot[np.stack([conf_a, conf_b], axis=1)]  # (M, 2)
    # Candidate time points with their robot (C,), in this layout: node enters, node
    # exits, pair enters, pair exits (each (M, 2) row-major), goals (NaN where none).
    cand_robot = np.concatenate(
        [node_robot, node_robot, conf_robot.ravel(), conf_robot.ravel(), np.arange(n_robots)]
    )
    cand_time = np.concatenate(
        [node_enter, node_exit, pair_enter.ravel(), pair_exit.ravel(), goal_time]
    )
    keep = ~np.isnan(cand_time)
    # Exact (robot, time) keys: times replaced by their rank among all distinct times;
    # the distinct keys are the time points, sorted by robot then time.
    distinct, rank = np.unique(cand_time[keep], return_inverse=True)
    tp_key, point = np.unique(
        cand_robot[keep].astype(np.int64) * distinct.size + rank, return_inverse=True
    )
    located = np.full(cand_time.size, -1, dtype=np.int64)  # (C,) time point of each candidate
    located[keep] = point
    tp_time = distinct[tp_key % distinct.size]
    tp_start = np.searchsorted(tp_key // distinct.size, np.arange(n_robots + 1), side="left")
    ends = np.cumsum([0, n_nodes, n_nodes, n_pairs, n_pairs])  # where each block starts

    return Problem(
        robot_ids=robot_ids,
        node_ids=node_ids,
        robot_start=np.searchsorted(node_robot, np.arange(n_robots + 1)),
        node_robot=node_robot,
        node_enter=node_enter,
        node_exit=node_exit,
        node_density=node_density,
        goal_time=goal_time,
        conf_a=conf_a,
        conf_b=conf_b,
        pair_enter=pair_enter,
        pair_exit=pair_exit,
        forced=forced,
        density_limits=DensityLimits.empty() if density_limits is None else density_limits,
        tp_time=tp_time,
        tp_start=tp_start,
        tp_pair_enter=located[ends[2] : ends[3]].reshape(-1, 2),
        tp_pair_exit=located[ends[3] : ends[4]].reshape(-1, 2),
        tp_node_enter=located[ends[0] : ends[1]],
        tp_node_exit=located[ends[1] : ends[2]],
        node_index=dict(zip(node_ids, range(len(node_ids)), strict=True))
        if node_index is None
        else node_index,
        realized=np.zeros(conf_a.size, dtype=bool),
        fixed_type=np.full(conf_a.size, -1, dtype=np.int8),
        tp_planned=tp_time,
        tp_passed=np.zeros(tp_time.size, dtype=bool),
    )
