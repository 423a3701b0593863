"""Where swept footprints interfere: boxes in the coordination space of each robot pair.

Broad phase: shapely's STRtree finds, in one bulk query, the path segments of
different robots whose bounding boxes, grown by the largest reach, overlap. Narrow
phase (numba): segment A of robot i is cut into *pieces* of at most
``resolution`` metres; for each piece, the stretch of segment B whose points lie
closer than ``R = r_i + r_j + margin`` to the piece is the intersection of B's
line with the piece's capsule of radius R, an interval found in closed form.
Each (piece, stretch) is a *box* ``[x0, x1] x [y0, y1]`` in the pair's
coordination space (arc lengths of i and j): the union of boxes is exactly the
set of configurations where a point of i's piece is within R of j's position,
so it covers every configuration where the two disks come within ``margin`` of
touching. A schedule that keeps every pair out of its boxes' interiors never
lets two disks overlap (the argument is in docs/paths.md).

Resolution only coarsens the arc lengths of robot i (the lower index) by up to
``resolution``; robot j's are exact. Where segment A stays within reach of the same
segments of other robots (a shared corridor), consecutive pieces run together into
one piece of up to COARSE_PIECE_M: its box is the union of theirs in both extents
(the stretch of a longer piece is the union of its parts' stretches), so nodes,
sections and pair times are the same as at full resolution; only a following
staircase over such a stretch has steps of up to COARSE_PIECE_M, which the
dependency plan makes anyway (``STAIRCASE_STEP_M``). Each candidate's range of pieces
within reach is exact (its end pieces tested as the narrow phase tests them), so runs
are cut only where a range starts or ends. A 250-robot one-way warehouse then has
0.54 M boxes instead of 1.7 M (0.83 M with the ranges' end pieces kept apart).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
import shapely

from service.core.threads import balanced_cuts, in_parts, parts_for
from service.geometry.paths import RobotPath, concatenated

__all__ = ["CO_DIRECTIONAL_DEG", "Boxes", "Segments", "TooComplex", "interference_boxes"]

# Two segments are co-directional when their headings differ by less than this (degrees):
# robots then drive the shared section the same way and one may follow the other.
CO_DIRECTIONAL_DEG = 30.0
# Consecutive segments whose unit headings' cross product is below this are one straight
# segment (1e-9 rad: only rounding of points placed on a straight line).
STRAIGHT_TOL = 1e-9
# Stretches of one piece on consecutive segments of a path touch at the shared vertex,
# equal up to rounding; closer than this (metres) they merge into one box.
MERGE_TOL = 1e-9
# Longest piece, metres, where a segment stays within reach of the same segments: the
# following staircase's step (``motion.dependencies.STAIRCASE_STEP_M``), so that runs
# of fine pieces along shared corridors make one box each.
COARSE_PIECE_M = 1.0
# Least pieces tried in a part of the narrow phase run on a thread of its own.
MIN_PART_PIECES = 50_000
# Segments queried per STRtree call, so a runaway candidate count is caught early.
QUERY_CHUNK = 4096


class TooComplex(ValueError):
    """The paths interfere in more places than the work bound allows (the API answers 413)."""


@dataclass(frozen=True, eq=False)
class Segments:
    """All robots' path segments, flattened. Shapes: G segments."""

    robot: np.ndarray  # (G,) int
    s0: np.ndarray  # (G,) float, arc length at the segment's start
    length: np.ndarray  # (G,) float
    p0: np.ndarray  # (G, 2) float
    p1: np.ndarray  # (G, 2) float

    @classmethod
    def of(cls, paths: Sequence[RobotPath]) -> Segments:
        """The straight segments of every path, robot by robot in path order.

        Consecutive path segments that continue in the same direction are one straight
        segment here (the arc lengths are the same either way): a straight aisle sent as
        100 points costs the geometry no more than sent as 2. All paths at once (robot
        by robot, 250 paths of 100 points took 10-20 ms).
        """
        points, arc, first_point = concatenated(paths)  # (N, 2), (N,), (R+1,)
        corner = np.zeros(arc.size, dtype=bool)  # (N,) the path turns there, or ends
        corner[1:-1] = _turns(points, arc)
        corner[first_point[:-1]] = corner[first_point[1:] - 1] = True
        at = np.flatnonzero(corner)  # (K,) corners, robot by robot
        robot = np.repeat(np.arange(len(paths)), np.diff(first_point))[at]  # (K,)
        start = np.flatnonzero(robot[1:] == robot[:-1])  # (G,) corners that start a segment
        return cls(
            robot[start],
            arc[at[start]],
            arc[at[start + 1]] - arc[at[start]],
            points[at[start]],
            points[at[start + 1]],
        )

    @property
    def heading(self) -> np.ndarray:
        """(G, 2) unit direction of travel."""
        return (self.p1 - self.p0) / self.length[:, None]


def _turns(points: np.ndarray, arc: np.ndarray) -> np.ndarray:
    """(N-2,) whether the path turns at each inner point of all paths joined (points
    (N, 2), arc (N,)); meaningless at a robot's first and last points, which are corners.

    A point is kept unless the segments on both sides point the same way (cross
    product and heading change within STRAIGHT_TOL), so merging never moves the path.
    """
    step = np.diff(arc)  # (N-1,): from a robot's last point to the next one's first too
    d = np.diff(points, axis=0) / np.where(step > 0.0, step, 1.0)[:, None]  # unit headings
    cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    dot = np.einsum("kd,kd->k", d[:-1], d[1:])
    return (np.abs(cross) > STRAIGHT_TOL) | (dot < 0.0)


@dataclass(frozen=True, eq=False)
class Boxes:
    """Interfering (piece, stretch) pairs, each a box in its robot pair's coordination space.

    Shapes: B boxes; side i is always the lower robot index (i < j).
    """

    i: np.ndarray  # (B,) int robot index
    j: np.ndarray  # (B,) int robot index, > i
    x0: np.ndarray  # (B,) float, robot i's piece [x0, x1]
    x1: np.ndarray
    y0: np.ndarray  # (B,) float, robot j's stretch [y0, y1]
    y1: np.ndarray
    co_directional: np.ndarray  # (B,) bool, headings within CO_DIRECTIONAL_DEG
    head_on: np.ndarray  # (B,) bool, headings within CO_DIRECTIONAL_DEG of opposite

    @property
    def size(self) -> int:
        return int(self.i.size)

    def take(self, index: np.ndarray) -> Boxes:
        """The boxes at ``index`` (an int array or a boolean mask)."""
        return Boxes(*(getattr(self, f)[index] for f in Boxes.__dataclass_fields__))


def _candidates(
    tree: shapely.STRtree, grown: np.ndarray, robot: np.ndarray, max_pairs: int
) -> tuple[np.ndarray, np.ndarray]:
    """Segment pairs (a, b) of robots robot[a] < robot[b] whose grown boxes overlap.

    Raises:
        TooComplex: more than ``max_pairs`` of them (checked chunk by chunk, so
            memory stays bounded however pathological the input).
    """
    parts_a, parts_b, total = [], [], 0
    for lo in range(0, grown.size, QUERY_CHUNK):
        q, t = tree.query(grown[lo : lo + QUERY_CHUNK])
        q = q + lo
        keep = robot[q] < robot[t]  # each robot pair once, never a robot with itself
        parts_a.append(q[keep])
        parts_b.append(t[keep])
        total += int(keep.sum())
        if total > max_pairs:
            raise TooComplex(
                f"paths come close in more than {max_pairs} segment pairs "
                "(max_interference_pairs): split the request or simplify the paths"
            )
    return np.concatenate(parts_a), np.concatenate(parts_b)


@numba.njit(cache=True, nogil=True)
def _line_capsule(
    bx: float,
    by: float,
    vx: float,
    vy: float,
    ax0: float,
    ay0: float,
    ax1: float,
    ay1: float,
    reach: float,
) -> tuple[float, float]:
    """Parameter interval (lo, hi) of the line (bx, by) + t (vx, vy), |v| = 1, inside the
    open capsule of radius ``reach`` around segment (ax0, ay0)-(ax1, ay1); lo >= hi when
    they do not meet. Scalars in and out: it runs per (piece, segment) pair, and array
    temporaries there cost the narrow phase a third of its time."""
    lo, hi = np.inf, -np.inf
    for cx, cy in ((ax0, ay0), (ax1, ay1)):  # the two end disks
        w0, w1 = bx - cx, by - cy
        beta = vx * w0 + vy * w1
        disc = beta * beta - (w0 * w0 + w1 * w1 - reach * reach)
        if disc > 0.0:
            root = np.sqrt(disc)
            lo, hi = min(lo, -beta - root), max(hi, -beta + root)
    d0, d1 = ax1 - ax0, ay1 - ay0
    ell = np.sqrt(d0 * d0 + d1 * d1)
    u0, u1 = d0 / ell, d1 / ell
    w0, w1 = bx - ax0, by - ay0
    # The rectangle: 0 <= along <= ell and |across| < reach, both linear in t.
    t_lo, t_hi = -np.inf, np.inf
    for base, slope, bound_lo, bound_hi in (
        (u0 * w0 + u1 * w1, u0 * vx + u1 * vy, 0.0, ell),
        (-u1 * w0 + u0 * w1, -u1 * vx + u0 * vy, -reach, reach),
    ):
        if abs(slope) < 1e-12:
            if not bound_lo <= base <= bound_hi:
                t_lo, t_hi = np.inf, -np.inf
        else:
            e0, e1 = (bound_lo - base) / slope, (bound_hi - base) / slope
            t_lo, t_hi = max(t_lo, min(e0, e1)), min(t_hi, max(e0, e1))
    if t_lo < t_hi:
        lo, hi = min(lo, t_lo), max(hi, t_hi)
    return lo, hi


@numba.njit(cache=True, nogil=True)
def _near_pieces(
    pair_a: np.ndarray,
    pair_b: np.ndarray,
    length: np.ndarray,
    p0: np.ndarray,
    p1: np.ndarray,
    reach: np.ndarray,
    resolution: float,
) -> tuple[np.ndarray, np.ndarray]:  # (C,) first and end piece of A within reach of B
    first = np.zeros(pair_a.size, dtype=np.int64)
    end = np.zeros(pair_a.size, dtype=np.int64)
    for c in range(pair_a.size):
        a, b = pair_a[c], pair_b[c]
        ux, uy = (p1[a, 0] - p0[a, 0]) / length[a], (p1[a, 1] - p0[a, 1]) / length[a]
        lo, hi = _line_capsule(
            p0[a, 0], p0[a, 1], ux, uy, p0[b, 0], p0[b, 1], p1[b, 0], p1[b, 1], reach[c]
        )
        lo, hi = max(lo, 0.0), min(hi, length[a])
        if lo < hi:
            n_pieces = max(1, int(np.ceil(length[a] / resolution)))
            step = length[a] / n_pieces
            k, k_end = min(int(lo / step), n_pieces - 1), min(int(np.ceil(hi / step)), n_pieces)
            # Rounded out to whole pieces, the range may end in pieces that only touch
            # B's capsule (or miss it by rounding): the narrow phase's own test of the
            # piece decides, so that every piece of the range makes a box and a run of
            # pieces inside it makes the union of their boxes.
            while k < k_end and not _piece_meets(a, b, k, n_pieces, length, p0, p1, reach[c]):
                k += 1
            while k_end > k and not _piece_meets(
                a, b, k_end - 1, n_pieces, length, p0, p1, reach[c]
            ):
                k_end -= 1
            first[c], end[c] = k, k_end
    return first, end


@numba.njit(cache=True, nogil=True)
def _piece(
    a: int, k: int, k_next: int, n_pieces: int, p0: np.ndarray, p1: np.ndarray
) -> tuple[float, float, float, float]:
    """Ends (x0, y0, x1, y1) in the plane of pieces k to k_next (excluded) of segment a."""
    dx, dy = p1[a, 0] - p0[a, 0], p1[a, 1] - p0[a, 1]
    f0, f1 = k / n_pieces, k_next / n_pieces
    if k_next < n_pieces:
        return p0[a, 0] + f0 * dx, p0[a, 1] + f0 * dy, p0[a, 0] + f1 * dx, p0[a, 1] + f1 * dy
    return p0[a, 0] + f0 * dx, p0[a, 1] + f0 * dy, p1[a, 0], p1[a, 1]


@numba.njit(cache=True, nogil=True)
def _stretch(
    b: int,
    piece: tuple[float, float, float, float],
    length: np.ndarray,
    p0: np.ndarray,
    p1: np.ndarray,
    reach: float,
) -> tuple[float, float]:
    """The stretch (lo, hi) of segment b, arc lengths from its start, within ``reach`` of
    ``piece`` (:func:`_piece`); lo >= hi when there is none."""
    vx = (p1[b, 0] - p0[b, 0]) / length[b]
    vy = (p1[b, 1] - p0[b, 1]) / length[b]
    qx0, qy0, qx1, qy1 = piece
    lo, hi = _line_capsule(p0[b, 0], p0[b, 1], vx, vy, qx0, qy0, qx1, qy1, reach)
    return max(lo, 0.0), min(hi, length[b])


@numba.njit(cache=True, nogil=True)
def _piece_meets(
    a: int,
    b: int,
    k: int,
    n_pieces: int,
    length: np.ndarray,
    p0: np.ndarray,
    p1: np.ndarray,
    reach: float,
) -> bool:
    """Piece k of segment a has a stretch of segment b within ``reach``."""
    lo, hi = _stretch(b, _piece(a, k, k + 1, n_pieces, p0, p1), length, p0, p1, reach)
    return lo < hi


@numba.njit(cache=True, nogil=True)
def _narrow_phase(
    pair_a: np.ndarray,  # (C,) int segment of the lower robot, sorted by (a, b)
    pair_b: np.ndarray,  # (C,) int segment of the higher robot
    near_first: np.ndarray,  # (C,) int, first piece of a within reach of b
    near_end: np.ndarray,  # (C,) int, end of those pieces (none: near_end <= near_first)
    seg_robot: np.ndarray,  # (G,) int
    s0: np.ndarray,  # (G,) float
    length: np.ndarray,  # (G,) float
    p0: np.ndarray,  # (G, 2) float
    p1: np.ndarray,  # (G, 2) float
    reach: np.ndarray,  # (C,) float, r_i + r_j + margin
    cos: np.ndarray,  # (C,) float, cosine between the two segments' headings
    cos_same: float,
    resolution: float,
    coarse: int,
    seg: np.ndarray,  # (N,) int out: segment a of each box
    robot: np.ndarray,  # (N,) int out: robot j
    span: np.ndarray,  # (4, N) float out: [x0, x1, y0, y1]
    way: np.ndarray,  # (2, N) bool out: [co-directional, head-on]
) -> int:
    # -> the boxes written (rows of span and way, so that later gathers read contiguous
    # memory), or -1 if more than N. A piece's stretches on consecutive segments of the
    # same robot j (its path cut at vertices) merge into one box: a 100-point path makes
    # no more boxes than drawn with its corners only.
    capacity = seg.size
    n = 0
    g = 0
    while g < pair_a.size:  # one group of candidates per segment a
        a, g_end = pair_a[g], g
        while g_end < pair_a.size and pair_a[g_end] == a:
            g_end += 1
        n_pieces = max(1, int(np.ceil(length[a] / resolution)))
        # Runs of up to ``coarse`` pieces, cut wherever a candidate's near range starts or
        # ends, so that each run lies wholly inside or outside every candidate's range
        # (every piece of which meets the candidate: its box is the union of theirs).
        first, end = near_first[g:g_end], near_end[g:g_end]
        cuts = np.sort(np.concatenate((first, end)))
        k, k_end, next_cut = first.min(), end.max(), 0
        while k < k_end:
            while cuts[next_cut] <= k:
                next_cut += 1
            k_next = min(k + coarse, cuts[next_cut])  # the last cut is k_end
            piece = _piece(a, k, k_next, n_pieces, p0, p1)
            x0 = s0[a] + k / n_pieces * length[a]
            x1 = s0[a] + k_next / n_pieces * length[a] if k_next < n_pieces else s0[a] + length[a]
            # The stretch being built: robot j (-1: none yet), [y0, y1], flags. The pass
            # c = g_end only emits the last stretch of the piece.
            j, y0, y1, same_way, head_on = -1, 0.0, 0.0, False, False
            for c in range(g, g_end + 1):
                if c < g_end:
                    if not near_first[c] <= k < near_end[c]:
                        continue
                    b = pair_b[c]
                    lo, hi = _stretch(b, piece, length, p0, p1, reach[c])
                    if not lo < hi:
                        continue
                    if seg_robot[b] == j and s0[b] + lo <= y1 + MERGE_TOL:
                        y1 = max(y1, s0[b] + hi)  # the stretch goes on
                        same_way |= cos[c] > cos_same
                        head_on |= cos[c] < -cos_same
                        continue
                if j >= 0:  # a new stretch starts, or the piece ends: emit the one built
                    if n == capacity:
                        return -1
                    seg[n], robot[n] = a, j
                    span[0, n], span[1, n], span[2, n], span[3, n] = x0, x1, y0, y1
                    way[0, n], way[1, n] = same_way, head_on
                    n += 1
                if c < g_end:
                    j, y0, y1 = seg_robot[b], s0[b] + lo, s0[b] + hi
                    same_way, head_on = cos[c] > cos_same, cos[c] < -cos_same
            k = k_next
        g = g_end
    return n


def interference_boxes(
    paths: Sequence[RobotPath], resolution: float, margin: float, max_pairs: int
) -> Boxes:
    """Every box where footprints of two robots come within ``margin`` of touching.

    Raises:
        TooComplex: more than ``max_pairs`` segment pairs lie within reach, or more
            than ``max_pairs`` boxes result (each box is ~100 bytes of work memory).
    """
    segs = Segments.of(paths)
    radius = np.array([p.radius for p in paths])  # (R,)
    lo = np.minimum(segs.p0, segs.p1)  # (G, 2) bounding boxes
    hi = np.maximum(segs.p0, segs.p1)
    tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
    # Bounding boxes grown by the largest reach: a superset of the pairs within reach
    # (a bulk ``dwithin`` query measured 20-50x slower); the narrow phase is exact.
    grow = 2.0 * float(radius.max()) + margin
    grown = shapely.box(lo[:, 0] - grow, lo[:, 1] - grow, hi[:, 0] + grow, hi[:, 1] + grow)
    a, b = _candidates(tree, grown, segs.robot, max_pairs)
    order = np.argsort(a * segs.robot.size + b)  # by (a, b): b along its path
    a, b = a[order], b[order]
    reach = radius[segs.robot[a]] + radius[segs.robot[b]] + margin  # (C,)
    cos = np.einsum("kd,kd->k", segs.heading[a], segs.heading[b])  # (C,)
    near_first, near_end = _near_pieces(a, b, segs.length, segs.p0, segs.p1, reach, resolution)

    # In parts of about equal pieces tried (each part whole segments a: a run's cuts need
    # all of the segment's candidates), on threads of their own, into one buffer. Every
    # box starts at a (piece, candidate) pair tried, so their count bounds a part's boxes:
    # allocated once (pages never written stay untouched); a growing buffer cost a third
    # of the phase at 1.7 M boxes, joining parts' own arrays ~10 ms at 0.8 M.
    tried = np.maximum(near_end - near_first, 0)  # (C,) pieces tried per candidate
    group_starts = np.flatnonzero(a[1:] != a[:-1]) + 1
    bounds = balanced_cuts(tried, parts_for(int(tried.sum()), MIN_PART_PIECES), group_starts)
    room = [min(int(tried[lo:hi].sum()), max_pairs + 1) for lo, hi in itertools.pairwise(bounds)]
    offset = np.concatenate([[0], np.cumsum(room)]).astype(np.int64)  # (parts+1,)
    seg, j = np.empty(offset[-1], dtype=np.int64), np.empty(offset[-1], dtype=np.int64)
    span, way = np.empty((4, offset[-1])), np.empty((2, offset[-1]), dtype=bool)
    cos_same = float(np.cos(np.radians(CO_DIRECTIONAL_DEG)))
    coarse = max(1, int(COARSE_PIECE_M // resolution))

    def narrow(part: int) -> int:  # the boxes of candidates in ``part``
        lo, hi, out = bounds[part], bounds[part + 1], slice(offset[part], offset[part + 1])
        return _narrow_phase(
            a[lo:hi], b[lo:hi], near_first[lo:hi], near_end[lo:hi],
            segs.robot, segs.s0, segs.length, segs.p0, segs.p1, reach[lo:hi], cos[lo:hi],
            cos_same, float(resolution), coarse, seg[out], j[out], span[:, out], way[:, out],
        )  # fmt: skip

    counts = in_parts(narrow, range(len(room)))
    if min(counts) < 0 or sum(counts) > max_pairs:
        raise TooComplex(
            f"paths interfere in more than {max_pairs} places (max_interference_pairs): "
            "split the request or simplify the paths"
        )
    n = counts[0]
    for part, count in enumerate(counts[1:], start=1):  # close the gaps between parts
        src = slice(offset[part], offset[part] + count)
        seg[n : n + count], j[n : n + count] = seg[src], j[src]
        span[:, n : n + count], way[:, n : n + count] = span[:, src], way[:, src]
        n += count
    seg, j, span, way = seg[:n], j[:n], span[:, :n], way[:, :n]
    return Boxes(segs.robot[seg], j, *span, *way)
