"""A brute-force reference implementation of the v1 contract, for tests only.

It reads the request *dict* (never the :class:`~service.core.problem.Problem`
arrays) and implements the contract as literally as possible in plain Python:

* updated times by fixpoint iteration over every time point of every robot
  (no events, no topological order), divergence detected by a pass count;
* node-level acyclicity by a depth-first search;
* fixed directions (a conflict's ``first``) by comparing every direction with them;
* density by enumerating every clique of the conflict graph and keeping the
  maximal ones;
* the optimum by enumerating all 2^M directions x 2^M types (those agreeing
  with the fixed directions).

It is deliberately slow and simple: it is the thing the fast code is compared to.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.learning.generate import GeneratorConfig, small_problem

OBJECTIVE_NAMES = ("avg_completion", "max_completion", "sync_completion", "avg_delay")


@dataclass(frozen=True)
class RefConflict:
    a: str
    b: str
    section: tuple[
        tuple[float, float], tuple[float, float]
    ]  # ((a_enter, a_exit), (b_enter, b_exit))
    first: str | None = None  # "a" or "b" when the direction is fixed


@dataclass(frozen=True)
class RefProblem:
    robot_ids: list[str]
    robot_nodes: list[list[dict[str, Any]]]  # per robot, the request's node dicts in path order
    node_robot: dict[str, int]
    node_density: dict[str, int]
    time_points: list[list[float]]  # per robot, sorted distinct times
    conflicts: list[RefConflict]
    limits: list[tuple[list[str], int]]  # explicit (nodes, max_robots)

    @property
    def n_conflicts(self) -> int:
        return len(self.conflicts)


def reference_problem(req: dict[str, Any]) -> RefProblem:
    """The contract's view of a (valid) request dict."""
    robot_nodes = [list(r["nodes"]) for r in req["robots"]]
    nodes = {n["id"]: n for ns in robot_nodes for n in ns}
    node_robot = {n["id"]: i for i, ns in enumerate(robot_nodes) for n in ns}
    times: list[set[float]] = [set() for _ in robot_nodes]
    for i, (robot, ns) in enumerate(zip(req["robots"], robot_nodes, strict=True)):
        for n in ns:
            times[i].update((n["enter"], n["exit"]))
        if robot.get("goal_time") is not None:
            times[i].add(robot["goal_time"])
    conflicts = []
    for c in req.get("conflicts", []):
        section = []
        for side in ("a", "b"):
            node = nodes[c[side]]
            enter = c.get(f"{side}_enter")
            exit_ = c.get(f"{side}_exit")
            enter = node["enter"] if enter is None else enter
            exit_ = node["exit"] if exit_ is None else exit_
            times[node_robot[c[side]]].update((enter, exit_))
            section.append((enter, exit_))
        conflicts.append(RefConflict(c["a"], c["b"], (section[0], section[1]), c.get("first")))
    return RefProblem(
        robot_ids=[r["id"] for r in req["robots"]],
        robot_nodes=robot_nodes,
        node_robot=node_robot,
        node_density={k: n.get("density", 1) for k, n in nodes.items()},
        time_points=[sorted(t) for t in times],
        conflicts=conflicts,
        limits=[(list(lim["nodes"]), lim["max_robots"]) for lim in req.get("density_limits", [])],
    )


def least_times(
    ref: RefProblem, a_first: Any, following: Any, skip: frozenset[int] = frozenset()
) -> list[list[float]] | None:
    """Least updated times T~ per robot and time point, or None when they do not exist.

    Conflicts in ``skip`` impose no rule (the realized conflicts of a re-schedule).

    Straight fixpoint iteration from T~ = T: raise every time point to what
    each rule demands until nothing changes. Every rule only copies a value
    or adds a fixed difference, so without a positive cycle it stops within
    (number of time points + 1) passes; still changing after that means the
    least times are unbounded.
    """
    T = ref.time_points
    Tn = [list(t) for t in T]
    index = [{t: k for k, t in enumerate(ts)} for ts in T]
    rules = []  # (to robot, to tp, from robot, from tp)
    for c, conf in enumerate(ref.conflicts):
        if c in skip:
            continue
        first, second = (0, 1) if a_first[c] else (1, 0)
        nodes = (conf.a, conf.b)
        fr, to = ref.node_robot[nodes[first]], ref.node_robot[nodes[second]]
        src_time = conf.section[first][0] if following[c] else conf.section[first][1]
        rules.append((to, index[to][conf.section[second][0]], fr, index[fr][src_time]))
    n_points = sum(len(t) for t in T)
    for _ in range(n_points + 2):
        changed = False
        for i, ts in enumerate(T):
            for k in range(1, len(ts)):
                need = Tn[i][k - 1] - ts[k - 1] + ts[k]  # D(k) >= D(k-1)
                if need > Tn[i][k]:
                    Tn[i][k], changed = need, True
        for to, k_to, fr, k_fr in rules:
            if Tn[fr][k_fr] > Tn[to][k_to]:
                Tn[to][k_to], changed = Tn[fr][k_fr], True
        if not changed:
            return Tn
    return None


def costs(ref: RefProblem, times: list[list[float]] | None) -> dict[str, float]:
    """The four objectives of updated times (all +inf when there are none)."""
    if times is None:
        return dict.fromkeys(OBJECTIVE_NAMES, float("inf"))
    completion = [t[-1] for t in times]
    n = len(completion)
    avg = sum(completion) / n
    delays = [
        sum(tn - t for tn, t in zip(tns, ts, strict=True)) / len(ts)
        for tns, ts in zip(times, ref.time_points, strict=True)
    ]
    return {
        "avg_completion": avg,
        "max_completion": max(completion),
        "sync_completion": avg + sum(abs(c - avg) for c in completion) / n,
        "avg_delay": sum(delays) / n,
    }


def is_acyclic(ref: RefProblem, a_first: Any) -> bool:
    """Node graph (path order + conflict directions) has no cycle: DFS with colours."""
    succ: dict[str, list[str]] = {v: [] for v in ref.node_robot}
    for ns in ref.robot_nodes:
        for u, v in itertools.pairwise(ns):
            succ[u["id"]].append(v["id"])
    for c, conf in enumerate(ref.conflicts):
        u, v = (conf.a, conf.b) if a_first[c] else (conf.b, conf.a)
        succ[u].append(v)
    colour = dict.fromkeys(succ, 0)  # 0 new, 1 on stack, 2 done

    def visit(u: str) -> bool:
        colour[u] = 1
        for v in succ[u]:
            if colour[v] == 1 or (colour[v] == 0 and not visit(v)):
                return False
        colour[u] = 2
        return True

    return all(colour[v] != 0 or visit(v) for v in succ)


def honours_fixed(ref: RefProblem, a_first: Any) -> bool:
    """Every conflict with a fixed direction passes its ``first`` side first."""
    return all(
        conf.first is None or bool(a_first[c]) == (conf.first == "a")
        for c, conf in enumerate(ref.conflicts)
    )


def density_groups(ref: RefProblem) -> list[tuple[frozenset[int], int]]:
    """(conflicts inside, following budget) of every maximal clique and explicit limit."""
    adj: dict[str, set[str]] = {}
    conflict_of: dict[frozenset[str], int] = {}
    for c, conf in enumerate(ref.conflicts):
        adj.setdefault(conf.a, set()).add(conf.b)
        adj.setdefault(conf.b, set()).add(conf.a)
        conflict_of[frozenset((conf.a, conf.b))] = c
    order = sorted(adj)
    cliques: list[tuple[str, ...]] = []

    def grow(clique: tuple[str, ...], start: int) -> None:
        cliques.append(clique)
        for j in range(start, len(order)):
            if all(order[j] in adj[u] for u in clique):
                grow((*clique, order[j]), j + 1)

    for i, v in enumerate(order):
        grow((v,), i + 1)
    maximal = [
        k for k in cliques if not any(all(w in adj[u] for u in k) for w in order if w not in k)
    ]

    def inside(nodes: tuple[str, ...] | list[str]) -> frozenset[int]:
        return frozenset(conflict_of[frozenset(p)] for p in itertools.combinations(nodes, 2))

    def budget(rho: int) -> int:
        return rho * (rho + 1) // 2 - 1

    groups = [(inside(k), budget(min(ref.node_density[v] for v in k))) for k in maximal]
    groups += [(inside(nodes), budget(rho)) for nodes, rho in ref.limits]
    return groups


def density_ok(groups: list[tuple[frozenset[int], int]], following: Any) -> bool:
    return all(sum(1 for c in inside if following[c]) <= h for inside, h in groups)


@dataclass(frozen=True)
class Candidate:
    a_first: tuple[bool, ...]
    following: tuple[bool, ...]
    costs: dict[str, float]


def feasible_assignments(ref: RefProblem) -> list[Candidate]:
    """Every acyclic, density-feasible assignment honouring the fixed directions, with its
    four costs (2^M x 2^M)."""
    m = ref.n_conflicts
    groups = density_groups(ref)
    directions = [
        d
        for d in itertools.product((False, True), repeat=m)
        if is_acyclic(ref, d) and honours_fixed(ref, d)
    ]
    types = [f for f in itertools.product((False, True), repeat=m) if density_ok(groups, f)]
    return [Candidate(d, f, costs(ref, least_times(ref, d, f))) for d in directions for f in types]


# --- problems ---------------------------------------------------------------------------------

TINY = GeneratorConfig(max_robots=4, max_conflicts=5)


def tiny_request(seed: int, objective: str = "avg_completion") -> dict[str, Any]:
    """A tiny random problem (2-4 robots, at most 5 conflicts) where types matter.

    Starts from the project generator and, depending on the seed, raises every
    node's density to 2-3 (so following-type is allowed and budgets can bind),
    cuts pair sections strictly inside their nodes, and adds an explicit
    density limit over the largest clique.
    """
    req = small_problem(seed, objective, TINY)
    rng = np.random.default_rng([seed, 7])
    nodes = {n["id"]: n for r in req["robots"] for n in r["nodes"]}
    if len(req["robots"]) >= 3 and rng.random() < 0.5:
        _add_triangle(rng, req)
    if rng.random() < 0.7:
        for n in nodes.values():
            n["density"] = int(rng.integers(2, 4))
    if rng.random() < 0.4:
        for c in req["conflicts"]:
            for side in ("a", "b"):
                node = nodes[c[side]]
                third = (node["exit"] - node["enter"]) / 3
                c[f"{side}_enter"] = round(node["enter"] + third, 3)
                c[f"{side}_exit"] = round(node["exit"] - third, 3)
    if rng.random() < 0.4 and req["conflicts"]:
        groups = _largest_clique(reference_problem(req))
        req["density_limits"] = [{"nodes": groups, "max_robots": int(rng.integers(1, 3))}]
    return req


def _renamed(req: dict[str, Any], prefix: str) -> dict[str, Any]:
    """``req`` with every robot and node id prefixed (to put two problems side by side)."""
    text = json.dumps({k: req[k] for k in ("robots", "conflicts", "density_limits") if k in req})
    robots = json.loads(text)["robots"]
    for r in robots:
        r["id"] = prefix + r["id"]
        for n in r["nodes"]:
            n["id"] = prefix + n["id"]
    conflicts = json.loads(text)["conflicts"]
    for c in conflicts:
        c["a"], c["b"] = prefix + c["a"], prefix + c["b"]
    limits = [
        {**lim, "nodes": [prefix + n for n in lim["nodes"]]}
        for lim in json.loads(text).get("density_limits", [])
    ]
    return {"robots": robots, "conflicts": conflicts, "density_limits": limits}


def side_by_side(seed: int) -> dict[str, Any] | None:
    """Two tiny problems with 1-3 conflicts each, as one request with two components."""
    found = []
    for k in range(seed * 50, seed * 50 + 50):
        req = tiny_request(k)
        if 1 <= len(req["conflicts"]) <= 3:
            found.append(req)
        if len(found) == 2:
            break
    if len(found) < 2:
        return None
    left, right = _renamed(found[0], "L"), _renamed(found[1], "R")
    return {key: left[key] + right[key] for key in left}


def fix_directions(req: dict[str, Any], seed: int, share: float = 0.5) -> dict[str, Any]:
    """A copy of ``req`` with about ``share`` of its conflicts given a random fixed direction.

    The directions are read off random node ranks increasing along every path
    (a random topological order), so together with path order they never form a
    cycle: the request stays valid.
    """
    rng = np.random.default_rng([seed, 11])
    rank = {
        n["id"]: r
        for robot in req["robots"]
        for n, r in zip(robot["nodes"], np.cumsum(rng.random(len(robot["nodes"]))), strict=True)
    }
    conflicts = [
        {**c, "first": "a" if rank[c["a"]] < rank[c["b"]] else "b"}
        if rng.random() < share
        else dict(c)
        for c in req.get("conflicts", [])
    ]
    return {**req, "conflicts": conflicts}


def _add_triangle(rng: np.random.Generator, req: dict[str, Any]) -> None:
    """Join one node of each of three robots pairwise (a clique whose budget can bind)."""
    robots = rng.choice(len(req["robots"]), size=3, replace=False)
    picks = [str(rng.choice([n["id"] for n in req["robots"][r]["nodes"]])) for r in robots]
    triangle = {frozenset(p) for p in itertools.combinations(picks, 2)}
    kept = [c for c in req["conflicts"] if frozenset((c["a"], c["b"])) in triangle]
    others = [c for c in req["conflicts"] if frozenset((c["a"], c["b"])) not in triangle]
    have = {frozenset((c["a"], c["b"])) for c in kept}
    kept += [{"a": min(p), "b": max(p)} for p in sorted(triangle - have, key=sorted)]
    req["conflicts"] = kept + others[: TINY.max_conflicts - len(kept)]


def _largest_clique(ref: RefProblem) -> list[str]:
    adj: dict[str, set[str]] = {}
    for conf in ref.conflicts:
        adj.setdefault(conf.a, set()).add(conf.b)
        adj.setdefault(conf.b, set()).add(conf.a)
    best: list[str] = []
    for size in range(2, len(adj) + 1):
        for nodes in itertools.combinations(sorted(adj), size):
            if all(v in adj[u] for u, v in itertools.combinations(nodes, 2)):
                best = list(nodes)
                break
    return best


def trap_request(objective: str = "avg_completion") -> dict[str, Any]:
    """Three robots with one node [0, 10] each and a conflict between every two.

    Each conflict's section is [8, 10] on one side and [0, 2] on the other, so
    the node cycle b->a, c->b, a->c (every a_first False) needs no waiting at
    all, while a->b->c->a (every a_first True) is a positive cycle.
    """
    return {
        "objective": objective,
        "robots": [
            {"id": r, "nodes": [{"id": r.upper(), "enter": 0.0, "exit": 10.0}]} for r in "abc"
        ],
        "conflicts": [
            {"a": a, "b": b, "a_enter": 8.0, "a_exit": 10.0, "b_enter": 0.0, "b_exit": 2.0}
            for a, b in (("A", "B"), ("B", "C"), ("C", "A"))
        ],
    }
