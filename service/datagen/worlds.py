"""The scenario kind's problems: graphs derived from seeded worlds, as the service derives them.

Problem ``i`` of seed ``s`` draws, from ``default_rng(SeedSequence([s, i]) state)``,
a kind uniformly from the training kinds, then a robot count (log-uniform in the
configured range) and a world seed. A world the service would refuse (its fixed
paths leave no collision-free order, or its cliques exceed the work budget) or
whose robots never interfere is redrawn: the next count and world seed of the
same stream, the kind kept, so the kinds stay as evenly drawn as configured and
only the sizes a kind cannot produce shift. The draw is deterministic; the
record says how many draws it took, and which parameters the kind drew.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.core.schemas import ScheduleRequest
from service.datagen.config import ScenarioConfig
from service.motion.plan import derived_request
from service.scenarios import KINDS, generate

__all__ = ["DrawnWorld", "draw_world", "robot_count"]


@dataclass(frozen=True)
class DrawnWorld:
    """One problem of the scenario kind: its graph-form request and where it came from."""

    request: ScheduleRequest
    kind: str
    robots: int  # robots of the world (the graph holds those that interfere)
    seed: int  # the world's seed: generate(kind, robots, seed) rebuilds it
    redraws: int  # worlds refused or conflict-free before this one
    drawn: dict[str, Any]  # the kind's parameters drawn for this seed (style, walls, ...)

    def world_record(self) -> dict[str, Any]:
        """What a dataset record keeps of the world, for splitting evaluations by kind (and
        by drawn parameter: wh_parked and wh_mixed draw every warehouse style, floor_mixed
        may have a wall with gaps, so a held-out style can be filtered out of them)."""
        return {
            "kind": self.kind,
            "robots": self.robots,
            "seed": self.seed,
            "redraws": self.redraws,
            "drawn": self.drawn,
        }


def robot_count(rng: np.random.Generator, low: int, high: int) -> int:
    """A robot count in ``low..high``, log-uniform (each doubling as likely as the next)."""
    return min(high, int(math.exp(rng.uniform(math.log(low), math.log(high + 1)))))


def draw_world(cfg: ScenarioConfig, seed: int) -> DrawnWorld:
    """The world of problem seed ``seed`` (see the module doc).

    Raises:
        RuntimeError: ``cfg.max_redraws`` draws gave no usable world (a kind that
            cannot produce a usable world at any size of the range).
    """
    rng = np.random.default_rng(seed)
    kind = cfg.kinds[int(rng.integers(len(cfg.kinds)))]
    for redraws in range(cfg.max_redraws):
        robots = robot_count(rng, *cfg.robots)
        world_seed = int(rng.integers(2**31))
        world = generate(kind, robots, world_seed)
        request = derived_request(world)
        if request is not None:
            drawn = {name: world.params[name] for name in KINDS[kind].choices}
            return DrawnWorld(request, kind, robots, world_seed, redraws, drawn)
    raise RuntimeError(f"{kind}: no usable world in {cfg.max_redraws} draws (seed {seed})")
