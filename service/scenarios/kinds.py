"""Named kinds of worlds: the families tests, benchmarks and training data draw from.

A kind fixes some parameters and draws others from a short list per seed, so
one kind covers a spread of layouts and timings while staying reproducible.
Held-out evaluation picks whole kinds (say, ``wh_two_lane`` or
``floor_passages``) that training never saw.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from service.scenarios.floor import floor
from service.scenarios.warehouse import STYLES, warehouse
from service.scenarios.world import World

__all__ = ["HELD_OUT", "KINDS", "Kind", "generate"]

# Stream id mixed into the seed for the per-kind parameter draws, so they never
# reuse the draws of the world itself.
CHOICE_STREAM = 1
START_RANGES = ((0.0, 5.0), (0.0, 10.0), (0.0, 20.0))  # seconds of start delay spread
RADIUS_MIX = (0.3, 0.4, 0.5)  # metres: small, standard and large robots


@dataclass(frozen=True)
class Kind:
    """A family of worlds: a generator, its fixed parameters, and parameters drawn per seed."""

    make: Callable[..., World]  # called as make(n_robots, seed=seed, **params)
    params: Mapping[str, Any] = field(default_factory=dict)
    choices: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)
    description: str = ""


KINDS: dict[str, Kind] = {
    "wh_one_way": Kind(
        warehouse,
        {"style": "one_way"},
        {"rack_length": (9.0, 12.0, 15.0), "start_time_range": START_RANGES},
        "warehouse, one-way aisles alternating, stations on one side",
    ),
    "wh_two_way": Kind(
        warehouse,
        {"style": "two_way"},
        {"rack_length": (9.0, 12.0, 15.0), "start_time_range": START_RANGES},
        "warehouse, single-lane aisles driven both ways",
    ),
    "wh_two_lane": Kind(
        warehouse,
        {"style": "two_lane"},
        {"station_sides": (1, 2), "start_time_range": START_RANGES},
        "warehouse, two lanes per aisle with right-hand traffic",
    ),
    "wh_parked": Kind(
        warehouse,
        {"parked_in_lanes": 0.25},
        {"style": STYLES, "start_time_range": START_RANGES},
        "warehouse where a quarter of the robots start on a lane",
    ),
    "wh_mixed": Kind(
        warehouse,
        {"radius_choices": RADIUS_MIX, "timed_fraction": 0.5},
        {"style": STYLES, "station_sides": (1, 2), "start_time_range": START_RANGES},
        "warehouse with mixed robot sizes and piecewise speeds",
    ),
    "floor_sparse": Kind(
        floor,
        {"density": 0.04},
        {"start_time_range": START_RANGES},
        "open floor, few obstacles",
    ),
    "floor_dense": Kind(
        floor,
        {"density": 0.2},
        {"start_time_range": START_RANGES},
        "open floor cluttered with disks and boxes",
    ),
    "floor_passages": Kind(
        floor,
        {"density": 0.05},
        {"walls": (1, 2, 3), "gaps_per_wall": (1, 2, 3), "start_time_range": START_RANGES},
        "floor split by walls, robots squeeze through their gaps",
    ),
    "floor_mixed": Kind(
        floor,
        {"radius_choices": RADIUS_MIX, "timed_fraction": 0.5},
        {"density": (0.05, 0.1, 0.15), "walls": (0, 1), "start_time_range": START_RANGES},
        "obstacle floor with mixed robot sizes and piecewise speeds",
    ),
}


# Kinds that training data leaves out and generalization is measured on: one warehouse
# style, the style-mixing warehouse kind (wh_mixed draws every style, the held-out one
# too) and one floor type (issue 13: "train on some warehouse styles and floor types,
# test on the others").
HELD_OUT = ("wh_two_lane", "wh_mixed", "floor_passages")


def generate(kind: str, n_robots: int, seed: int) -> World:
    """The world of ``kind`` for ``n_robots`` and ``seed`` (the same every time)."""
    if kind not in KINDS:
        raise KeyError(f"unknown kind {kind!r}; known: {', '.join(KINDS)}")
    spec = KINDS[kind]
    rng = np.random.default_rng([seed, CHOICE_STREAM])
    drawn = {name: options[rng.integers(len(options))] for name, options in spec.choices.items()}
    world = spec.make(n_robots, seed=seed, **spec.params, **drawn)
    return dataclasses.replace(world, kind=kind)
