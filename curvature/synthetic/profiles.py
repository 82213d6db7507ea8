"""Planar profiles made of straight segments and circular arcs, with exact curvature.

Machined parts are, to a good approximation, extrusions and revolutions of such profiles: flat
faces joined by fillets of constant radius. A profile here is a polygon whose corners are
rounded by tangent arcs (:func:`filleted_polygon`); a corner of radius 0 stays sharp. Along
the profile everything is known exactly: position, unit tangent, outward normal and signed
curvature (positive where the curve bends away from its outward normal, the library's sign
convention, DESIGN.md section 3), and the arc-length distance to the nearest *joint*, where the
curvature jumps (a line meeting an arc), which is what a finite neighborhood cannot resolve.

Conventions: a closed profile is traversed counter-clockwise, so the outward normal is the
tangent turned clockwise, ``n = (t_y, -t_x)``. Open profiles (for revolution) use the same
rule, traversed so that the outside is on the right.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError

__all__ = ["Profile", "Segment", "filleted_polygon"]


@dataclass(frozen=True)
class Segment:
    """A line (``radius == 0``) or a circular arc of a profile.

    Attributes
    ----------
    start : tuple of float
        First point (x, y).
    direction : tuple of float
        Unit tangent at the start.
    length : float
        Arc length.
    curvature : float
        Signed curvature: 0 on a line, +1/r on an arc turning left (counter-clockwise, convex
        for a CCW profile), -1/r on one turning right (concave).
    label : str
        Region name of the segment's points (e.g. ``"face"``, ``"fillet"``).
    """

    start: tuple
    direction: tuple
    length: float
    curvature: float
    label: str

    def evaluate(self, s: np.ndarray):
        """Points, unit tangents and curvature at arc lengths ``s`` (m,) from the start.

        Returns
        -------
        points, tangents : ndarray, shape (m, 2)
        curvature : ndarray, shape (m,)
        """
        s = np.asarray(s, np.float64)
        p0 = np.asarray(self.start, np.float64)
        t0 = np.asarray(self.direction, np.float64)
        kappa = self.curvature
        if kappa == 0.0:
            return p0 + s[:, None] * t0, np.broadcast_to(t0, (s.size, 2)).copy(), \
                np.zeros(s.size)
        # Turning angle phi = kappa s; tangent rotates by phi; the point moves along the chord.
        phi = kappa * s
        c, sn = np.cos(phi), np.sin(phi)
        tangents = np.column_stack([c * t0[0] - sn * t0[1], sn * t0[0] + c * t0[1]])
        left = np.array([-t0[1], t0[0]])  # the centre lies at start + left / kappa
        offset = (np.sin(phi)[:, None] * t0 + (1.0 - np.cos(phi))[:, None] * left) / kappa
        return p0 + offset, tangents, np.full(s.size, kappa)


@dataclass(frozen=True)
class Profile:
    """A chain of tangent-continuous (or sharp-cornered) segments.

    Attributes
    ----------
    segments : tuple of Segment
    closed : bool
        The last segment ends where the first starts.
    """

    segments: tuple
    closed: bool

    @property
    def length(self) -> float:
        return float(sum(seg.length for seg in self.segments))

    @property
    def labels(self) -> tuple:
        """Distinct segment labels in order of first appearance."""
        return tuple(dict.fromkeys(seg.label for seg in self.segments))

    def _offsets(self) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum([seg.length for seg in self.segments])])

    def joints(self) -> np.ndarray:
        """Arc lengths where the curvature jumps (between segments of different curvature, and
        at sharp corners), shape (j,)."""
        offsets = self._offsets()
        segs = self.segments
        jumps = []
        count = len(segs)
        for i in range(count if self.closed else count - 1):
            a, b = segs[i], segs[(i + 1) % count]
            end_dir = a.evaluate(np.array([a.length]))[1][0]
            sharp = float(np.dot(end_dir, b.direction)) < 1.0 - 1e-12
            if sharp or a.curvature != b.curvature:
                jumps.append(offsets[i + 1])
        return np.asarray(jumps, np.float64)

    def evaluate(self, s: np.ndarray):
        """Exact geometry at arc lengths ``s`` (m,) along the whole profile.

        Returns
        -------
        points, tangents, normals : ndarray, shape (m, 2)
            Outward normal ``(t_y, -t_x)``.
        curvature : ndarray, shape (m,)
        segment : ndarray, shape (m,), int64
            Index of the segment of every point.
        joint_distance : ndarray, shape (m,)
            Arc-length distance to the nearest joint (inf when there is none).
        """
        s = np.asarray(s, np.float64)
        offsets = self._offsets()
        seg = np.clip(np.searchsorted(offsets, s, side="right") - 1, 0, len(self.segments) - 1)
        m = s.size
        points, tangents, kappa = np.empty((m, 2)), np.empty((m, 2)), np.empty(m)
        for i, segment in enumerate(self.segments):
            rows = np.flatnonzero(seg == i)
            if rows.size:
                points[rows], tangents[rows], kappa[rows] = segment.evaluate(s[rows] - offsets[i])
        normals = np.column_stack([tangents[:, 1], -tangents[:, 0]])
        joints = self.joints()
        if joints.size == 0:
            dist = np.full(m, np.inf)
        else:
            gap = np.abs(s[:, None] - joints[None, :])
            if self.closed:
                gap = np.minimum(gap, self.length - gap)
            dist = gap.min(axis=1)
        return points, tangents, normals, kappa, seg, dist


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def filleted_polygon(vertices, radii, labels, corner_labels, *, closed: bool = True) -> Profile:
    """A polygon whose corners are rounded by tangent circular arcs.

    Parameters
    ----------
    vertices : array_like, shape (v, 2)
        Corners, counter-clockwise for a closed profile (outside on the right of travel).
    radii : array_like, shape (v,)
        Fillet radius per corner; 0 keeps the corner sharp. On an open profile the first and
        last vertices are its ends and their radii are ignored.
    labels : sequence of str, length v (closed) or v - 1 (open)
        Region name of each edge ``vertices[i] -> vertices[i + 1]``.
    corner_labels : sequence of str, length v
        Region name of each corner's fillet arc.
    closed : bool

    Returns
    -------
    Profile

    Raises
    ------
    ParameterError
        When two fillets on one edge need more than its length, or an edge has zero length.
    """
    v = np.asarray(vertices, np.float64)
    r = np.asarray(radii, np.float64)
    count = v.shape[0]
    edges = count if closed else count - 1
    dirs = [_unit(v[(i + 1) % count] - v[i]) for i in range(edges)]
    lengths = [float(np.linalg.norm(v[(i + 1) % count] - v[i])) for i in range(edges)]
    if min(lengths) <= 0.0:
        raise ParameterError("profile edges must have positive length")
    # Per corner: setback along both edges, the arc's turn and signed curvature.
    setback = np.zeros(count)
    turn = np.zeros(count)
    for c in range(count):
        if not closed and c in (0, count - 1):
            continue
        d_in, d_out = dirs[(c - 1) % edges], dirs[c % edges]
        cross = d_in[0] * d_out[1] - d_in[1] * d_out[0]
        turn[c] = np.arctan2(cross, float(np.dot(d_in, d_out)))
        if r[c] > 0.0:
            setback[c] = r[c] * np.tan(abs(turn[c]) / 2.0)
    segments = []
    for e in range(edges):
        a, b = e, (e + 1) % count
        start = v[a] + setback[a] * dirs[e]
        length = lengths[e] - setback[a] - setback[b]
        if length < -1e-12:
            raise ParameterError(f"fillets of corners {a} and {b} overlap on their edge")
        if length > 1e-12:
            segments.append(Segment(tuple(start), tuple(dirs[e]), length, 0.0, labels[e]))
        if (closed or b != count - 1) and r[b] > 0.0 and turn[b] != 0.0:
            arc_start = v[b] - setback[b] * dirs[e]
            kappa = np.sign(turn[b]) / r[b]
            segments.append(Segment(tuple(arc_start), tuple(dirs[e]), abs(turn[b]) * r[b],
                                    float(kappa), corner_labels[b]))
    return Profile(tuple(segments), closed)
