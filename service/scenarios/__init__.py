"""Seeded worlds for the paths form: warehouses and obstacle floors with their robots.

``generate(kind, n_robots, seed)`` builds a named kind (``KINDS``);
``warehouse`` and ``floor`` take every parameter directly. Each returns a
``World`` whose ``to_request()`` is a paths-form request body.
"""

from service.scenarios.fleet import FleetParams
from service.scenarios.floor import FloorParams, floor
from service.scenarios.kinds import HELD_OUT, KINDS, Kind, generate
from service.scenarios.warehouse import STYLES, WarehouseParams, warehouse
from service.scenarios.world import World

__all__ = [
    "HELD_OUT",
    "KINDS",
    "STYLES",
    "FleetParams",
    "FloorParams",
    "Kind",
    "WarehouseParams",
    "World",
    "floor",
    "generate",
    "warehouse",
]
