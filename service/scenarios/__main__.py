"""Command line: write seeded worlds and their paths-form request bodies.

    python -m service.scenarios --kind wh_two_lane --robots 50 --seed 0 \\
        [--out world.json] [--request req.json]
    python -m service.scenarios --kind floor_dense --robots 100 --seed 0 --count 20 \\
        --out worlds/ [--request requests/]

With ``--count N`` the seeds are ``seed .. seed + N - 1`` and ``--out`` and
``--request`` name directories. Without ``--out`` or ``--request`` a single
world is printed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tqdm import tqdm

from service.scenarios.kinds import KINDS, generate
from service.scenarios.world import World


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line's options."""
    parser = argparse.ArgumentParser(prog="python -m service.scenarios", description=__doc__)
    parser.add_argument("--kind", required=True, choices=sorted(KINDS))
    parser.add_argument("--robots", type=int, required=True, help="2 to 250")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--count", type=int, default=1, help="worlds to write (seeds in a row)")
    parser.add_argument("--out", type=Path, help="world JSON (a directory with --count > 1)")
    parser.add_argument("--request", type=Path, help="request body (a directory with --count)")
    parser.add_argument("--objective", default="avg_completion")
    args = parser.parse_args(argv)
    if args.count < 1:
        parser.error("--count must be at least 1")
    if args.count > 1 and not (args.out or args.request):
        parser.error("--count > 1 needs --out and/or --request directories")
    return args


def target(path: Path | None, many: bool, world: World, seed: int) -> Path | None:
    """Where one world's file goes: ``path`` itself, or a file named after it in ``path``."""
    if path is None or not many:
        return path
    path.mkdir(parents=True, exist_ok=True)
    return path / f"{world.kind}-n{len(world.robots)}-s{seed}.json"


def main(argv: list[str] | None = None) -> None:
    """Generate and write the worlds the command line asks for."""
    args = parse_args(argv)
    many = args.count > 1
    seeds = range(args.seed, args.seed + args.count)
    for seed in tqdm(seeds, desc=args.kind, unit="world", disable=not many):
        world = generate(args.kind, args.robots, seed)
        out = target(args.out, many, world, seed)
        request = target(args.request, many, world, seed)
        if out:
            out.write_text(world.to_json())
        if request:
            request.write_text(json.dumps(world.to_request(args.objective)))
        if not (out or request):
            sys.stdout.write(world.to_json(indent=1) + "\n")


if __name__ == "__main__":
    main()
