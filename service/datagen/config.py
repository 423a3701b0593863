"""What determines a dataset's content: one frozen config, stored in its manifest.

Example: ``DatasetConfig(kind="scenario", problems=2000, top=3,
scenario=ScenarioConfig(kinds=("wh_one_way", "floor_dense"), robots=(5, 100)))``.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from typing import Any

from service.core.schemas import OBJECTIVES
from service.learning.generate import GeneratorConfig
from service.scenarios import KINDS

__all__ = ["DATASET_KINDS", "DatasetConfig", "ScenarioConfig", "config_dict"]

DATASET_KINDS = ("small", "stitched", "scenario")
# Draws of one problem's world (robot count and world seed) before giving up: a kind's
# worlds are refused mostly at large robot counts (floor_dense accepted 7 of 30 seeds at
# 25 robots and none at 50, bench/cases.py), and a redraw of the count from a
# log-uniform 5-100 lands at 25 or fewer robots half of the time.
MAX_REDRAWS = 100


@dataclass(frozen=True)
class ScenarioConfig:
    """Which worlds the ``scenario`` kind draws from (:mod:`service.scenarios`).

    ``kinds``: the training kinds, each problem's drawn uniformly (leave the held-out
    kinds out); ``robots``: the inclusive range of the robot count, drawn log-uniformly
    so that most problems are small enough for CP-SAT to prove their labels.
    """

    kinds: tuple[str, ...] = tuple(KINDS)
    robots: tuple[int, int] = (5, 100)
    max_redraws: int = MAX_REDRAWS

    def __post_init__(self) -> None:
        """Refuse unknown kinds and empty ranges before any work is done."""
        unknown = sorted(set(self.kinds) - set(KINDS))
        if unknown or not self.kinds:
            raise ValueError(f"scenario kinds: unknown {unknown} or none; known: {list(KINDS)}")
        if not 2 <= self.robots[0] <= self.robots[1]:
            raise ValueError(f"scenario robots: need 2 <= low <= high, got {self.robots}")


@dataclass(frozen=True)
class DatasetConfig:
    """Everything that determines a dataset's content."""

    problems: int = 10_000
    seed: int = 0
    top: int = 10  # L: best assignments kept per problem and objective
    objectives: tuple[str, ...] = OBJECTIVES
    shard_size: int = 100
    solve_time_limit_s: float = 10.0  # per CP-SAT solve; small problems take ~10 ms
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)
    # "small": the published generator; "stitched": problems of robots in
    # ``stitched_robots`` with conflicts per robot uniform in ``stitched_density``,
    # labelled by CP-SAT's best within ``solve_time_limit_s`` (not always proven);
    # "scenario": graphs derived from generated worlds (``scenario``), labelled by the
    # exact portfolio with each label's gap (:mod:`service.datagen.labels`).
    kind: str = "small"
    stitched_robots: tuple[int, int] = (10, 40)
    stitched_density: tuple[float, float] = (1.5, 4.0)
    scenario: ScenarioConfig | None = None  # the scenario kind's draws (its defaults if None)

    def __post_init__(self) -> None:
        """Resolve the scenario kind's draws, so that the manifest states them."""
        if self.kind not in DATASET_KINDS:
            raise ValueError(f"dataset kind {self.kind!r}; known: {DATASET_KINDS}")
        if self.kind == "scenario" and self.scenario is None:
            object.__setattr__(self, "scenario", ScenarioConfig())
        if self.kind != "scenario" and self.scenario is not None:
            raise ValueError("scenario settings are for the scenario kind only")


def config_dict(cfg: DatasetConfig) -> dict[str, Any]:
    """The config as it reads back from the manifest (tuples become lists).

    ``scenario`` is left out of the other kinds' configs, so that datasets built
    before it existed still match their manifest and resume.
    """
    data = json.loads(json.dumps(asdict(cfg)))
    if data["scenario"] is None:
        del data["scenario"]
    return data
