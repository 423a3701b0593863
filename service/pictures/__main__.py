"""``python -m service.pictures``: draw a saved paths-form request/response pair.

Example::

    python -m service.pictures --request req.json --response resp.json \
        --world world.json --out pictures/ --what layout gantt gif
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable, Sequence
from pathlib import Path

from service.pictures.animation import write_gif
from service.pictures.gantt import draw_gantt
from service.pictures.layout import draw_layout
from service.pictures.plan import Json

# What each --what choice draws, and the file it writes in --out.
FILE_NAMES = {"layout": "layout.png", "gantt": "gantt.png", "gif": "run.gif"}


def _load(path: Path) -> Json:
    """Read a JSON object from a file."""
    return json.loads(path.read_text())


def _parser() -> argparse.ArgumentParser:
    """The command line: inputs, output folder, which pictures, GIF pacing."""
    parser = argparse.ArgumentParser(prog="python -m service.pictures", description=__doc__)
    parser.add_argument("--request", type=Path, required=True, help="paths-form request JSON")
    parser.add_argument("--response", type=Path, required=True, help="200 response JSON")
    parser.add_argument("--world", type=Path, help="world JSON: bounds and obstacles")
    parser.add_argument("--out", type=Path, required=True, help="folder for the pictures")
    parser.add_argument(
        "--what",
        nargs="+",
        choices=list(FILE_NAMES),
        default=list(FILE_NAMES),
        help="pictures to draw (default: all)",
    )
    parser.add_argument("--fps", type=float, default=10.0, help="GIF frames per second")
    parser.add_argument("--max-frames", type=int, default=200, help="most GIF frames")
    return parser


def main(argv: Sequence[str] | None = None) -> None:
    """Draw the chosen pictures into ``--out`` and print their paths."""
    args = _parser().parse_args(argv)
    request, response = _load(args.request), _load(args.response)
    world = _load(args.world) if args.world else None
    drawers: dict[str, Callable[[Path], Path]] = {
        "layout": lambda path: draw_layout(request, response, world, path),
        "gantt": lambda path: draw_gantt(response, path),
        "gif": lambda path: write_gif(request, response, world, path, args.fps, args.max_frames),
    }
    for what in dict.fromkeys(args.what):
        print(drawers[what](args.out / FILE_NAMES[what]))


if __name__ == "__main__":
    main()
