"""The three pictures and the CLI write valid files of the intended shape."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from service.pictures import draw_gantt, draw_layout, write_gif
from service.pictures.__main__ import main
from service.pictures.animation import frame_times, robot_motion
from tests.pictures.conftest import Json

# The GIF frames aim at ~600 px on their long side.
GIF_LONG_SIDE_PX = 600
FEW_FRAMES = 12


def _many_robots(count: int) -> Json:
    """A response of ``count`` robots each driving 10 m east after a 1 s wait."""
    return {
        "schedule": [
            {"robot": f"r{k:03d}", "completion": 11.0, "delay": 1.0, "nodes": []}
            for k in range(count)
        ],
        "trajectories": [
            {"robot": f"r{k:03d}", "points": [[0, 0, k], [1, 0, k], [11, 10, k]]}
            for k in range(count)
        ],
    }


def test_layout_is_a_png(
    request_body: Json, response_body: Json, world_body: Json, tmp_path: Path
) -> None:
    path = draw_layout(request_body, response_body, world_body, tmp_path / "sub" / "layout.png")
    with Image.open(path) as image:
        assert image.format == "PNG"
        assert image.width > 400 and image.height > 400


def test_layout_needs_only_the_request(request_body: Json, tmp_path: Path) -> None:
    with Image.open(draw_layout(request_body, path=tmp_path / "layout.png")) as image:
        assert image.format == "PNG"


def test_gantt_is_a_png_that_grows_with_the_fleet(response_body: Json, tmp_path: Path) -> None:
    with Image.open(draw_gantt(response_body, tmp_path / "small.png")) as small:
        assert small.format == "PNG"
        small_height = small.height
    with Image.open(draw_gantt(_many_robots(100), tmp_path / "large.png")) as large:
        assert large.height > 10 * small_height


def test_gif_is_animated_and_small(
    request_body: Json, response_body: Json, world_body: Json, tmp_path: Path
) -> None:
    path = write_gif(
        request_body, response_body, world_body, tmp_path / "run.gif", max_frames=FEW_FRAMES
    )
    with Image.open(path) as image:
        assert image.format == "GIF"
        assert 1 < image.n_frames <= FEW_FRAMES
        assert max(image.size) == GIF_LONG_SIDE_PX


def test_frame_times_cover_the_run_at_fps_or_fewer(response_body: Json) -> None:
    times = frame_times(response_body, fps=10, max_frames=1000)
    assert (times[0], times[-1], len(times)) == (0.0, 13.0, 131)
    assert len(frame_times(response_body, fps=10, max_frames=20)) == 20


def test_motion_shows_the_waiting_robot_and_hides_absent_ones(response_body: Json) -> None:
    motion = robot_motion(response_body, ["amr-a", "amr-b", "amr-c"], np.array([0.5, 5.0, 12.0]))
    assert motion.present.tolist() == [[True, True, False], [True, True, True], [False, True, True]]
    assert motion.waiting.tolist() == [[False] * 3, [False, True, False], [False] * 3]
    assert motion.positions[1].tolist() == [[5, 0], [5, -1], [2, 1]]


def test_gif_rejects_bad_pacing(request_body: Json, response_body: Json, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="max_frames"):
        write_gif(request_body, response_body, path=tmp_path / "run.gif", max_frames=1)


def test_cli_writes_the_chosen_pictures(
    request_body: Json, response_body: Json, world_body: Json, tmp_path: Path
) -> None:
    files = {"request": request_body, "response": response_body, "world": world_body}
    for name, body in files.items():
        (tmp_path / f"{name}.json").write_text(json.dumps(body))
    args = [f"--{name}={tmp_path / f'{name}.json'}" for name in files]
    main([*args, f"--out={tmp_path / 'out'}", "--max-frames=5"])
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "gantt.png",
        "layout.png",
        "run.gif",
    ]
    main([*args, f"--out={tmp_path / 'gantt_only'}", "--what", "gantt"])
    assert [p.name for p in (tmp_path / "gantt_only").iterdir()] == ["gantt.png"]


def test_gif_needs_a_trajectory_of_a_known_robot(request_body: Json, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no trajectory"):
        write_gif(request_body, {"trajectories": []}, path=tmp_path / "run.gif")
