"""bench.overhead: resampled paths keep their route and timing; a tiny run end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.overhead import main, resampled
from service.core.path_schemas import PathsRequest
from service.geometry.paths import RobotPath


def _robot(body: dict, k: int) -> RobotPath:
    return RobotPath.from_wire(PathsRequest.model_validate(body).robots[k])


def test_resampled_paths_keep_corners_ends_and_planned_times() -> None:
    body = {
        "objective": "avg_completion",
        "robots": [
            {"id": "a", "path": [[0, 0], [4, 0], [4, 3]], "radius": 0.3, "speed": 0.5},
            {"id": "b", "path": [[0, 1], [2, 1], [9, 1]], "radius": 0.3, "times": [1, 3, 10]},
        ],
    }
    out = resampled(body, 20)
    for k in range(2):
        before, after = _robot(body, k), _robot(out, k)
        assert 20 <= after.points.shape[0] <= 20 + before.points.shape[0]
        corners = {tuple(p) for p in before.points.tolist()}
        assert corners <= {tuple(p) for p in after.points.tolist()}
        assert after.length == pytest.approx(before.length, abs=1e-9)
        assert after.finish_time == pytest.approx(before.finish_time, abs=1e-9)
        s = np.linspace(0.0, before.length, 37)
        np.testing.assert_allclose(after.time_at(s), before.time_at(s), atol=1e-9)
        np.testing.assert_allclose(after.position_at(s), before.position_at(s), atol=1e-9)


def test_quick_run_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert main(["--quick", "--out", str(out), "--sizes", "6", "12"]) == 0
    for name in ("tables.md", "results.json", "results.csv", "overhead.png"):
        assert (out / name).stat().st_size > 0
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert [r["robots"] for r in rows] == [6, 12]
    for r in rows:
        assert r["collision_free"] and not r["refused_by_default_bounds"]
        # two plans (quick): each median is a mean, so the overhead is the sum of the parts
        assert r["overhead_s"] == pytest.approx(r["graph_s"] + r["motion_s"], rel=1e-12)
        assert 0 < r["graph_s"] <= r["graph_max_s"] and 0 < r["motion_s"] <= r["motion_max_s"]
