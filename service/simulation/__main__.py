"""``python -m service.simulation``: replay or execute a saved paths-form answer, with delays.

Examples::

    # execute the answer's dependency plan; robot amr-003 starts 20 s late and
    # amr-010 stops for 5 s at t = 30 s
    python -m service.simulation --request req.json --response resp.json \\
        --delay amr-003:start:20 --delay amr-010:30:5
    # ten random disturbances (late starts, stops, slow-downs), seeded
    python -m service.simulation --request req.json --response resp.json --random 10 --seed 1
    # play back the answer's trajectories as they are
    python -m service.simulation --request req.json --response resp.json --playback

Prints a summary (clearance, overlaps, deadlocks, mean and max completion) and
writes the full report as JSON with ``--out``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from service.core.path_schemas import (
    DisturbanceIn,
    PathRobotIn,
    SimulationRequest,
    SimulationResponse,
)
from service.simulation.simulate import simulate

__all__ = ["main", "parse_delay", "random_disturbances"]

# Random disturbances: a third each late starts, stops and slow-downs, up to this long (s).
RANDOM_MAX_DURATION_S = 30.0


def parse_delay(text: str, robots: dict[str, PathRobotIn]) -> DisturbanceIn:
    """``ROBOT:START:DURATION[:FACTOR]``; START ``start`` means the robot's own start time."""
    parts = text.split(":")
    if len(parts) not in (3, 4) or parts[0] not in robots:
        raise argparse.ArgumentTypeError(f"bad --delay '{text}' (ROBOT:START:DURATION[:FACTOR])")
    robot = robots[parts[0]]
    start = robot.begin if parts[1] == "start" else float(parts[1])
    factor = float(parts[3]) if len(parts) == 4 else 0.0
    return DisturbanceIn(robot=robot.id, start=start, duration=float(parts[2]), factor=factor)


def random_disturbances(
    robots: list[PathRobotIn], count: int, horizon: float, seed: int
) -> list[DisturbanceIn]:
    """``count`` seeded disturbances: late starts, stops and slow-downs within ``horizon`` s."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        robot = robots[int(rng.integers(len(robots)))]
        kind = int(rng.integers(3))
        begin = robot.begin
        start = begin if kind == 0 else float(rng.uniform(begin, max(begin, horizon)))
        factor = float(rng.uniform(0.2, 0.8)) if kind == 2 else 0.0
        duration = float(rng.uniform(1.0, RANDOM_MAX_DURATION_S))
        out.append(DisturbanceIn(robot=robot.id, start=start, duration=duration, factor=factor))
    return out


def summary(report: SimulationResponse) -> str:
    """A few lines for the terminal."""
    done = [t for t in report.completion.values() if t is not None]
    lines = [
        f"collision free: {report.collision_free}   min clearance: {report.min_clearance_m} m",
        f"overlaps: {len(report.overlaps)}   deadlocked: {report.deadlocked or 'none'}",
        f"completion: mean {np.mean(done):.3f} s, max {np.max(done):.3f} s "
        f"({len(done)} of {len(report.completion)} robots finished)",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the simulation the command line asks for; exit status 1 on overlap or deadlock."""
    parser = argparse.ArgumentParser(
        prog="python -m service.simulation",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--request", type=Path, required=True, help="paths-form request body")
    parser.add_argument("--response", type=Path, required=True, help="its 200 answer")
    parser.add_argument("--playback", action="store_true", help="replay the trajectories")
    parser.add_argument(
        "--delay", action="append", default=[], help="ROBOT:START:DURATION[:FACTOR]"
    )
    parser.add_argument("--random", type=int, default=0, help="this many random disturbances")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, help="write the full report (JSON) here")
    args = parser.parse_args(argv)
    request = json.loads(args.request.read_text())
    response = json.loads(args.response.read_text())
    robots = [PathRobotIn.model_validate(r) for r in request["robots"]]
    by_id = {r.id: r for r in robots}
    if args.playback:
        body = SimulationRequest(robots=robots, trajectories=response["trajectories"])
    else:
        horizon = max(t["points"][-1][0] for t in response["trajectories"])
        disturbances = [parse_delay(d, by_id) for d in args.delay]
        disturbances += random_disturbances(robots, args.random, horizon, args.seed)
        body = SimulationRequest(
            robots=robots, dependencies=response["dependencies"], disturbances=disturbances
        )
    report = simulate(body)
    print(summary(report))
    if args.out:
        args.out.write_text(report.model_dump_json(indent=1))
    return 0 if report.collision_free and not report.deadlocked else 1


if __name__ == "__main__":
    raise SystemExit(main())
