"""The run as an animated GIF: robots as discs moving along their trajectories.

Frames are sampled evenly over the whole run (at ``fps`` frames per simulated
second, or fewer when that would exceed ``max_frames``: playback is then faster
than real time, and the caption says by how much). Each frame draws the robots
present at its time as discs of their radius, a waiting robot with an orange
rim, over the floor and the faint paths. The static background is drawn once
and the discs blitted onto it, and the GIF shares one small palette so that
Pillow stores only the changed part of each frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import EllipseCollection, LineCollection
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure
from PIL import Image

from service.pictures.geometry import positions_at
from service.pictures.layout import draw_world
from service.pictures.plan import Json, plot_bounds, robot_paths, robot_waits, trajectories
from service.pictures.style import (
    LABEL_FONT_SIZE,
    MAX_LABELLED_ROBOTS,
    WAIT_COLOUR,
    new_figure,
    robot_colours,
    world_figure_size,
)

__all__ = ["write_gif", "frame_times", "robot_motion", "Motion", "Frames"]

# A 6-inch long side at 100 dpi: ~600 px frames.
LONG_SIDE_IN = 6.0
MAX_ASPECT = 2.0
PATH_ALPHA = 0.35
PATH_WIDTH = 0.8
DISC_ALPHA = 0.8
DISC_EDGE_WIDTH = 1.0
WAIT_EDGE_WIDTH = 3.0
CAPTION_FONT_SIZE = 9
CAPTION_POSITION = (0.01, 0.99)  # axes fraction, top left
AXES_MARGIN = 0.02  # figure fraction around the floor
# One palette for the whole GIF, built by Pillow's fast octree from a few evenly
# spaced frames. Measured on 3 and 300 robots (200 frames): 64 colours give files
# ~25 % smaller than 255, a mean error under 4/255 and a white that stays white
# (median cut tinted it).
PALETTE_COLOURS = 64
PALETTE_SAMPLE_FRAMES = 8
MS_PER_S = 1000.0
WAIT_RGBA = np.array(to_rgba(WAIT_COLOUR))

Frames = list[np.ndarray]


def frame_times(response: Json, fps: float, max_frames: int) -> np.ndarray:
    """Evenly spaced frame times from the first robot's start to the last robot's end.

    ``fps`` frames per simulated second, capped at ``max_frames`` (at least 2).
    """
    spans = np.array([[p[0, 0], p[-1, 0]] for p in trajectories(response).values()])
    start, end = float(spans[:, 0].min()), float(spans[:, 1].max())
    count = min(max_frames, math.ceil((end - start) * fps) + 1)
    return np.linspace(start, end, max(count, 2))


@dataclass(frozen=True)
class Motion:
    """Where the robots are at each frame time.

    Shapes: ``positions (F, R, 2)``, ``present (F, R)``, ``waiting (F, R)``.
    """

    robots: list[str]
    positions: np.ndarray
    present: np.ndarray
    waiting: np.ndarray


def _during(times: np.ndarray, intervals: list[tuple[float, float]]) -> np.ndarray:
    """Whether each time lies in one of the closed intervals. Shapes: ``(F,)`` -> ``(F,)``."""
    inside = np.zeros(len(times), dtype=bool)
    for start, end in intervals:
        inside |= (times >= start) & (times <= end)
    return inside


def robot_motion(response: Json, robots: list[str], times: np.ndarray) -> Motion:
    """Positions, presence and waiting of ``robots`` at the frame ``times``."""
    paths = trajectories(response)
    waits = robot_waits(response)
    located = [positions_at(paths[robot], times) for robot in robots]
    present = np.stack([p for _, p in located], axis=1)
    waiting = np.stack([_during(times, waits[robot]) for robot in robots], axis=1)
    return Motion(
        robots=robots,
        positions=np.stack([xy for xy, _ in located], axis=1),
        present=present,
        waiting=waiting & present,
    )


def _background(request: Json, world: Json | None) -> tuple[Figure, Axes]:
    """The static figure (floor, obstacles, faint paths) and its axes."""
    bounds = plot_bounds(request, world)
    figure = new_figure(*world_figure_size(bounds, LONG_SIDE_IN, MAX_ASPECT))
    axes = figure.add_axes((AXES_MARGIN, AXES_MARGIN, 1 - 2 * AXES_MARGIN, 1 - 2 * AXES_MARGIN))
    draw_world(axes, bounds, world)
    paths = robot_paths(request)
    colours = robot_colours(paths)
    axes.add_collection(
        LineCollection(
            list(paths.values()),
            colors=[colours[r] for r in paths],
            lw=PATH_WIDTH,
            alpha=PATH_ALPHA,
        )
    )
    axes.set_xticks([])
    axes.set_yticks([])
    return figure, axes


def _playback_caption(t: float, speed_up: float) -> str:
    """The frame's time, with the playback speed when it is not real time."""
    caption = f"t = {t:.1f} s"
    return caption if math.isclose(speed_up, 1.0) else f"{caption}   (playback x{speed_up:.1f})"


def _discs(axes: Axes, diameters: np.ndarray) -> EllipseCollection:
    """The robots' footprints as one collection of discs, blitted frame by frame."""
    discs = EllipseCollection(
        diameters,
        diameters,
        np.zeros(len(diameters)),
        units="xy",
        offsets=np.zeros((len(diameters), 2)),
        offset_transform=axes.transData,
        animated=True,
    )
    axes.add_collection(discs, autolim=False)
    return discs


def _show_robots(discs: EllipseCollection, colours: np.ndarray, motion: Motion, k: int) -> None:
    """Move the discs to frame ``k``: absent robots transparent, waiting ones with a wide
    orange rim."""
    present, waiting = motion.present[k], motion.waiting[k]
    fill = colours.copy()
    fill[:, 3] = DISC_ALPHA * present
    rim = np.where(waiting[:, None], WAIT_RGBA, colours)
    rim[:, 3] = present
    discs.set_offsets(motion.positions[k])
    discs.set_facecolors(fill)
    discs.set_edgecolors(rim)
    discs.set_linewidths(np.where(waiting, WAIT_EDGE_WIDTH, DISC_EDGE_WIDTH))


def _render_frames(
    request: Json, response: Json, world: Json | None, times: np.ndarray, fps: float
) -> Frames:
    """RGB frames ``(H, W, 3)`` of the robots at ``times`` (ids written when few).

    Robots absent from the request are skipped (their radius is unknown).
    """
    radius = {robot["id"]: float(robot["radius"]) for robot in request["robots"]}
    motion = robot_motion(response, [r for r in trajectories(response) if r in radius], times)
    palette = robot_colours(robot_paths(request))
    colours = np.array([palette[r] for r in motion.robots]).reshape(-1, 4)

    figure, axes = _background(request, world)
    discs = _discs(axes, np.array([2 * radius[r] for r in motion.robots]))
    labels = [
        axes.text(0, 0, robot, fontsize=LABEL_FONT_SIZE, ha="center", va="center", animated=True)
        for robot in motion.robots
        if len(motion.robots) <= MAX_LABELLED_ROBOTS
    ]
    caption = axes.text(
        *CAPTION_POSITION,
        "",
        transform=axes.transAxes,
        va="top",
        fontsize=CAPTION_FONT_SIZE,
        animated=True,
    )
    canvas = figure.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(figure.bbox)
    speed_up = (times[-1] - times[0]) / (len(times) - 1) * fps
    frames: Frames = []
    for k, t in enumerate(times):
        canvas.restore_region(background)
        _show_robots(discs, colours, motion, k)
        axes.draw_artist(discs)
        for j in np.flatnonzero(motion.present[k]) if labels else []:
            labels[j].set_position(motion.positions[k, j])
            axes.draw_artist(labels[j])
        caption.set_text(_playback_caption(float(t), speed_up))
        axes.draw_artist(caption)
        frames.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
    return frames


def _save_gif(frames: Frames, path: Path, fps: float) -> None:
    """Write frames as a looping GIF on one shared palette (no dithering).

    The palette comes from a few evenly spaced frames stacked together, so that
    robots appearing late keep their colour; identical palettes let Pillow store
    only each frame's changed box.
    """
    sample = np.linspace(0, len(frames) - 1, min(PALETTE_SAMPLE_FRAMES, len(frames))).astype(int)
    palette = Image.fromarray(np.vstack([frames[k] for k in sample])).quantize(
        PALETTE_COLOURS, method=Image.Quantize.FASTOCTREE
    )
    images = [
        Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE)
        for frame in frames
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=round(MS_PER_S / fps),
        loop=0,
    )


def write_gif(
    request: Json,
    response: Json,
    world: Json | None = None,
    path: str | Path = "run.gif",
    fps: float = 10,
    max_frames: int = 200,
) -> Path:
    """Animate a paths-form response as a looping GIF and return its path.

    Args:
        request: the paths-form request (paths and radii).
        response: the answer; its ``trajectories`` are played.
        world: optional ``bounds`` and ``obstacles`` (polygons).
        path: where to write the GIF.
        fps: frames per second of playback, and per simulated second when the
            run fits in ``max_frames``.
        max_frames: the most frames to write (the file size grows with them).
    """
    if fps <= 0 or max_frames < 2:
        raise ValueError(f"need fps > 0 and max_frames >= 2, got {fps} and {max_frames}")
    if not set(trajectories(response)) & {robot["id"] for robot in request["robots"]}:
        raise ValueError("the response has no trajectory of a robot in the request to animate")
    times = frame_times(response, fps, max_frames)
    path = Path(path)
    _save_gif(_render_frames(request, response, world, times, fps), path, fps)
    return path
