"""Random coordination problems in the v1 request format (numpy only, no torch).

Two families, both deterministic by seed:

* :func:`small_problem` mirrors the published training set (2 to 8 robots,
  up to 14 conflicts). Distributions, per robot: start U(0, 5); 1 to 4 nodes;
  node duration U(1, 4); gap between nodes U(0.5, 3); goal time (70 %) the
  last exit + U(0.5, 3). Node density 1 (50 %), 2 (30 %) or 3 (20 %). Conflicts:
  U{1..14} distinct node pairs of different robots drawn with weight
  exp(-|time gap| / 3), so robots near each other in time interfere more, as
  on real paths. Each side's pair section is the whole node (40 %) or a random
  sub-interval at any position inside it (60 %). Times are rounded to 1 ms.
* :func:`stitched_problem` concatenates small problems into a large one
  (10 to 250+ robots), shifting each part in time, and adds conflicts between
  nodes of different parts until the requested conflicts-per-robot density is
  reached: density, not robot count, is what makes exact solving hard.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["GeneratorConfig", "small_problem", "stitched_problem"]

Request = dict[str, Any]


@dataclass(frozen=True)
class GeneratorConfig:
    """Knobs of the small-problem generator (defaults: the published ranges)."""

    min_robots: int = 2
    max_robots: int = 8
    max_nodes_per_robot: int = 4
    max_conflicts: int = 14
    time_scale: float = 1.0  # multiplies every time: the model must not care
    closeness: float = 3.0  # time scale of the pair-selection weight exp(-gap / closeness)


def _robot_nodes(rng: np.random.Generator, prefix: str, n_nodes: int, start: float) -> list[dict]:
    """Nodes of one robot in path order, strictly separated."""
    nodes, t = [], start
    for p in range(n_nodes):
        enter = t
        exit_ = enter + rng.uniform(1.0, 4.0)
        node: dict[str, Any] = {"id": f"{prefix}/{p}", "enter": enter, "exit": exit_}
        u = rng.random()
        if u >= 0.5:
            node["density"] = 2 if u < 0.8 else 3
        nodes.append(node)
        t = exit_ + rng.uniform(0.5, 3.0)
    return nodes


def _pair_section(rng: np.random.Generator, node: dict) -> tuple[float, float]:
    """A pair section inside ``node``: the whole node or a sub-interval anywhere in it."""
    if rng.random() < 0.4:
        return node["enter"], node["exit"]
    lo, hi = np.sort(rng.uniform(node["enter"], node["exit"], size=2))
    return float(lo), float(max(hi, lo + 1e-3 * (node["exit"] - node["enter"])))


def _add_conflicts(
    rng: np.random.Generator,
    request: Request,
    count: int,
    closeness: float,
    allowed: np.ndarray | None = None,
) -> None:
    """Add up to ``count`` new conflicts between nodes of different robots.

    ``allowed`` (optional, (V, V) bool) restricts which node pairs may be joined.
    """
    nodes = [(ri, n) for ri, r in enumerate(request["robots"]) for n in r["nodes"]]
    robot = np.array([ri for ri, _ in nodes])
    mid = np.array([(n["enter"] + n["exit"]) / 2 for _, n in nodes])
    weight = np.exp(-np.abs(mid[:, None] - mid[None, :]) / closeness)
    weight *= robot[:, None] != robot[None, :]
    if allowed is not None:
        weight *= allowed
    index = {n["id"]: i for i, (_, n) in enumerate(nodes)}
    for c in request["conflicts"]:
        i, j = index[c["a"]], index[c["b"]]
        weight[i, j] = weight[j, i] = 0.0
    weight = np.triu(weight, k=1).ravel()
    count = min(count, int(np.count_nonzero(weight)))
    if count <= 0:
        return
    picks = rng.choice(weight.size, size=count, replace=False, p=weight / weight.sum())
    for flat in np.sort(picks):
        i, j = divmod(int(flat), len(nodes))
        (a_enter, a_exit), (b_enter, b_exit) = (
            _pair_section(rng, nodes[i][1]),
            _pair_section(rng, nodes[j][1]),
        )
        request["conflicts"].append(
            {
                "a": nodes[i][1]["id"],
                "b": nodes[j][1]["id"],
                "a_enter": a_enter,
                "a_exit": a_exit,
                "b_enter": b_enter,
                "b_exit": b_exit,
            }
        )


def _round_times(request: Request, scale: float) -> Request:
    """Scale every time and round to 1 ms of the unscaled clock (keeps order strict)."""

    def fix(x: float) -> float:
        return round(x, 3) * scale

    for robot in request["robots"]:
        for node in robot["nodes"]:
            node["enter"], node["exit"] = fix(node["enter"]), fix(node["exit"])
        if "goal_time" in robot:
            robot["goal_time"] = fix(robot["goal_time"])
    for c in request["conflicts"]:
        for key in ("a_enter", "a_exit", "b_enter", "b_exit"):
            c[key] = fix(c[key])
    _clamp_pair_times(request)
    return request


def _clamp_pair_times(request: Request) -> None:
    """After rounding, keep pair sections inside their nodes and non-empty."""
    nodes = {n["id"]: n for r in request["robots"] for n in r["nodes"]}
    for c in request["conflicts"]:
        for side in ("a", "b"):
            node = nodes[c[side]]
            enter = min(max(c[f"{side}_enter"], node["enter"]), node["exit"])
            exit_ = min(max(c[f"{side}_exit"], node["enter"]), node["exit"])
            if not exit_ > enter:
                enter, exit_ = node["enter"], node["exit"]
            c[f"{side}_enter"], c[f"{side}_exit"] = enter, exit_


def _robots(
    rng: np.random.Generator, cfg: GeneratorConfig, n_robots: int, tag: str, t0: float
) -> list[dict]:
    """``n_robots`` random robots with ids prefixed by ``tag``."""
    robots = []
    for i in range(n_robots):
        rid = f"{tag}r{i}"
        nodes = _robot_nodes(
            rng, rid, int(rng.integers(1, cfg.max_nodes_per_robot + 1)), t0 + rng.uniform(0.0, 5.0)
        )
        robot: dict[str, Any] = {"id": rid, "nodes": nodes}
        if rng.random() < 0.7:
            robot["goal_time"] = nodes[-1]["exit"] + rng.uniform(0.5, 3.0)
        robots.append(robot)
    return robots


def _part(
    rng: np.random.Generator, cfg: GeneratorConfig, n_robots: int, tag: str, t0: float
) -> Request:
    """Robots and their own conflicts: one small problem, ids prefixed by ``tag``."""
    request: Request = {"robots": _robots(rng, cfg, n_robots, tag, t0), "conflicts": []}
    _add_conflicts(rng, request, int(rng.integers(1, cfg.max_conflicts + 1)), cfg.closeness)
    return request


def small_problem(
    seed: int | np.random.Generator,
    objective: str = "avg_completion",
    cfg: GeneratorConfig = GeneratorConfig(),
) -> Request:
    """One random small problem (a request dict without options)."""
    rng = np.random.default_rng(seed)
    n_robots = int(rng.integers(cfg.min_robots, cfg.max_robots + 1))
    request = {"objective": objective, **_part(rng, cfg, n_robots, "", 0.0)}
    return _round_times(request, cfg.time_scale)


def stitched_problem(
    seed: int,
    n_robots: int,
    conflicts_per_robot: float,
    objective: str = "avg_completion",
    cfg: GeneratorConfig = GeneratorConfig(),
) -> Request:
    """A problem of ``n_robots`` robots stitched from small problems.

    Parts (each a small problem with its own conflicts) start at random offsets
    over a horizon growing with sqrt(n_robots); conflicts between nodes of
    different parts are added until the problem has about
    ``conflicts_per_robot * n_robots`` conflicts (as far as node pairs allow).
    """
    rng = np.random.default_rng(seed)
    request: Request = {"objective": objective, "robots": [], "conflicts": []}
    part_of_node: list[int] = []
    horizon = 2.0 * np.sqrt(n_robots)
    while len(request["robots"]) < n_robots:
        size = min(
            int(rng.integers(cfg.min_robots, cfg.max_robots + 1)), n_robots - len(request["robots"])
        )
        part = _part(rng, cfg, size, f"p{len(set(part_of_node))}", rng.uniform(0.0, horizon))
        part_of_node += [len(set(part_of_node))] * sum(len(r["nodes"]) for r in part["robots"])
        request["robots"] += part["robots"]
        request["conflicts"] += part["conflicts"]
    parts = np.array(part_of_node)
    missing = int(round(conflicts_per_robot * n_robots)) - len(request["conflicts"])
    _add_conflicts(rng, request, missing, cfg.closeness, allowed=parts[:, None] != parts[None, :])
    return _round_times(request, cfg.time_scale)
