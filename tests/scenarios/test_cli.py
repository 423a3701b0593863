"""The command line writes worlds and request bodies."""

from __future__ import annotations

import json
from pathlib import Path

from service.scenarios import World
from service.scenarios.__main__ import main


def test_one_world_and_its_request(tmp_path: Path) -> None:
    out, request = tmp_path / "world.json", tmp_path / "req.json"
    main(
        [
            "--kind",
            "wh_one_way",
            "--robots",
            "6",
            "--seed",
            "2",
            "--out",
            str(out),
            "--request",
            str(request),
        ]
    )
    world = World.from_json(out.read_text())
    assert json.loads(request.read_text()) == world.to_request()


def test_count_writes_a_directory_of_worlds(tmp_path: Path) -> None:
    main(["--kind", "floor_sparse", "--robots", "4", "--count", "3", "--out", str(tmp_path)])
    files = sorted(tmp_path.glob("*.json"))
    assert [f.name for f in files] == [f"floor_sparse-n4-s{s}.json" for s in range(3)]
