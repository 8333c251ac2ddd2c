"""Support polygon of the contacts and the static stability margin.

The support polygon is the convex hull of the ground projections (x, y) of the contact points; z is up.
Everything here is vectorised over leading sample dimensions: `contact_points` has shape (..., k, 3) and an
optional boolean `active` (..., k) selects the contacts touching the ground at each sample, so a gait whose
support set changes over time is one array call. For k contacts the hull edges are found by testing all
k (k - 1) ordered pairs at once (an ordered pair i -> j is a counter-clockwise hull edge when no active
point lies strictly to its right), which is exact, loop-free and cheap for the handful of feet a robot has.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from legkit.stability._validation import bool_mask, float_array

# Relative tolerance of the hull test: a point counts as "on the left" of an edge unless it lies to the right
# by more than this fraction of (edge length x scene extent), so collinear contacts do not flicker.
_HULL_TOLERANCE = 1e-10


@dataclass(frozen=True)
class SupportEdges:
    """Counter-clockwise support-polygon edges of every sample, one slot per ordered contact pair.

    start, end: (..., E, 2) edge end points in the ground plane, E = k (k - 1);
    valid: (..., E) whether the slot is a hull edge at that sample (for a two-contact support both
    directions of the segment are edges, i.e. both sides of the line are "outside");
    start_index, end_index: (E,) contact indices of each slot.
    """

    start: np.ndarray
    end: np.ndarray
    valid: np.ndarray
    start_index: np.ndarray
    end_index: np.ndarray

    @property
    def outward_normal(self) -> np.ndarray:
        """(..., E, 2) unit normals pointing out of the polygon (to the right of each CCW edge)."""
        direction = self.end - self.start
        length = np.linalg.norm(direction, axis=-1, keepdims=True)
        direction = direction / np.where(length > 0.0, length, 1.0)
        return np.stack([direction[..., 1], -direction[..., 0]], axis=-1)


def _contacts(contact_points: npt.ArrayLike, active: npt.ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
    points = float_array(contact_points, "contact_points", last=3, min_ndim=2)
    if points.shape[-2] < 1:
        raise ValueError("contact_points must hold at least one contact point")
    mask = bool_mask(active, "active", points.shape[:-1])
    if not np.all(np.any(mask, axis=-1)):
        first = np.argwhere(~np.any(mask, axis=-1))[0]
        raise ValueError(f"active selects no contact at sample {tuple(int(i) for i in first)}: a support needs one")
    return points, mask


@dataclass(frozen=True)
class _Hull:
    """Hull edges in component-first layout for speed: every array is (E, T) over T flattened samples (the
    sample axis last, so reductions over edges or contacts are element-wise passes over long rows)."""

    x: np.ndarray  # (k, T) contact ground coordinates
    y: np.ndarray
    mask: np.ndarray  # (k, T)
    start_index: np.ndarray  # (E,)
    end_index: np.ndarray
    sx: np.ndarray  # (E, T) edge start
    sy: np.ndarray
    dx: np.ndarray  # (E, T) edge vector
    dy: np.ndarray
    length: np.ndarray
    valid: np.ndarray

    @property
    def any_edge(self) -> np.ndarray:
        return np.any(self.valid, axis=0)


def _hull(x: np.ndarray, y: np.ndarray, mask: np.ndarray) -> _Hull:
    """Ordered pairs i -> j of the active contacts (k, T) that are CCW hull edges (module docstring).

    The side test runs once per unordered pair: j -> i sees every point on the opposite side of i -> j
    (cross products negate), so both directions come from one pass."""
    k = x.shape[0]
    a, b = np.triu_indices(k, 1)
    sx, sy = x[a], y[a]
    dx, dy = x[b] - sx, y[b] - sy
    length = np.sqrt(dx * dx + dy * dy)
    extent = np.sqrt(np.max((x - x[:1]) ** 2 + (y - y[:1]) ** 2, axis=0))
    tolerance = _HULL_TOLERANCE * length * (extent + 1e-300)
    both = mask[a] & mask[b] & (length > tolerance + 1e-300)
    forward, backward = both.copy(), both
    for other in range(k):  # k is the number of feet: a handful; the work is vectorised over pairs and samples
        cross = dx * (y[other] - sy) - dy * (x[other] - sx)
        ignored = ~mask[other]
        forward &= (cross >= -tolerance) | ignored
        backward &= (cross <= tolerance) | ignored
    i, j = np.concatenate([a, b]), np.concatenate([b, a])
    return _Hull(
        x, y, mask, i, j,
        np.concatenate([sx, x[b]]), np.concatenate([sy, y[b]]), np.concatenate([dx, -dx]), np.concatenate([dy, -dy]),
        np.concatenate([length, length]), np.concatenate([forward, backward]),
    )


def _flatten(points: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]:
    """(x, y, mask) as (k, T) arrays and the sample shape."""
    shape = points.shape[:-2]
    k = points.shape[-2]
    flat = points.reshape(-1, k, 3)
    contiguous = np.ascontiguousarray  # rows of (k, T) are long unit-stride vectors: the fast layout
    return contiguous(flat[:, :, 0].T), contiguous(flat[:, :, 1].T), contiguous(mask.reshape(-1, k).T), shape


def support_edges(contact_points: npt.ArrayLike, active: npt.ArrayLike | None = None) -> SupportEdges:
    """Hull edges of the active contacts' ground projections, vectorised over samples (see SupportEdges).

    contact_points: (..., k, 3) world positions [m]; active: optional (..., k) bool (default all True).
    Raises ValueError when a sample has no active contact, or on NaN/inf.
    """
    points, mask = _contacts(contact_points, active)
    x, y, flat_mask, shape = _flatten(points, mask)
    hull = _hull(x, y, flat_mask)
    edges = len(hull.start_index)

    def back(a: np.ndarray) -> np.ndarray:
        return a.T.reshape(shape + (edges,))

    start = np.stack([back(hull.sx), back(hull.sy)], axis=-1)
    end = np.stack([back(hull.sx + hull.dx), back(hull.sy + hull.dy)], axis=-1)
    return SupportEdges(start, end, back(hull.valid), hull.start_index, hull.end_index)


def _signed_distance(px: np.ndarray, py: np.ndarray, hull: _Hull) -> np.ndarray:
    """Signed distance (T,) of points (T,) to the hull of the active contacts; > 0 strictly inside."""
    rx, ry = px - hull.sx, py - hull.sy
    length_sq = hull.length * hull.length
    s = np.clip((rx * hull.dx + ry * hull.dy) / np.where(length_sq > 0.0, length_sq, 1.0), 0.0, 1.0)
    segment = np.where(hull.valid, np.hypot(rx - s * hull.dx, ry - s * hull.dy), np.inf)
    # Segments include their end points; only a support without any edge (one point) needs the vertices.
    vertex = np.where(hull.mask, np.hypot(px - hull.x, py - hull.y), np.inf)
    any_edge = hull.any_edge
    distance = np.where(any_edge, np.min(segment, axis=0), np.min(vertex, axis=0))
    # Strictly left of every CCW edge; a line or point support has edges in both directions, so nothing is inside.
    cross = hull.dx * ry - hull.dy * rx
    inside = any_edge & np.all((cross > 0.0) | ~hull.valid, axis=0)
    return np.where(inside, distance, -distance)


def static_stability_margin(
    com: npt.ArrayLike, contact_points: npt.ArrayLike, active: npt.ArrayLike | None = None
) -> np.ndarray:
    """Signed distance [m] from the ground projection of the COM to the support-polygon boundary.

    com: (..., 3) world COM [m] (only x, y are used); contact_points: (..., k, 3); active: optional (..., k)
    bool. Leading dimensions broadcast. Returns (...,): positive when the projection is strictly inside the
    polygon (statically stable), zero on the boundary, negative outside (minus the distance to the polygon).
    A one- or two-contact support (a point or a line) has no interior, so the margin is never positive.
    """
    point = float_array(com, "com", last=3)
    points, mask = _contacts(contact_points, active)
    shape = np.broadcast_shapes(point.shape[:-1], points.shape[:-2], mask.shape[:-1])
    points = np.broadcast_to(points, shape + points.shape[-2:])
    mask = np.broadcast_to(mask, shape + mask.shape[-1:])
    x, y, flat_mask, _ = _flatten(points, mask)
    flat_point = np.broadcast_to(point, shape + (3,)).reshape(-1, 3)
    return _signed_distance(flat_point[:, 0], flat_point[:, 1], _hull(x, y, flat_mask)).reshape(shape)


def support_polygon(contact_points: npt.ArrayLike, active: npt.ArrayLike | None = None) -> np.ndarray:
    """Counter-clockwise vertices (m, 2) of the support polygon of one sample.

    contact_points: (k, 3) world positions [m]; active: optional (k,) bool. Andrew's monotone chain keeps only
    strict corners, so collinear contacts give the two end points (m = 2) and coincident ones a single point.
    """
    points, mask = _contacts(contact_points, active)
    if points.ndim != 2:
        raise ValueError(f"contact_points must be (k, 3) for one sample, got shape {points.shape}")
    xy = np.unique(points[mask][:, :2], axis=0)  # sorted by x then y, as the monotone chain needs
    if len(xy) <= 2:
        return xy
    return convex_hull_2d(xy)


def convex_hull_2d(xy: np.ndarray) -> np.ndarray:
    """CCW hull of distinct 2-D points sorted lexicographically (Andrew's monotone chain), strict corners only."""
    scale = float(np.max(np.abs(xy - xy[0]))) or 1.0

    def half(sequence: np.ndarray) -> list[np.ndarray]:
        chain: list[np.ndarray] = []
        for p in sequence:
            while len(chain) >= 2:
                a, b = chain[-2], chain[-1]
                if (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) > 1e-12 * scale * scale:
                    break
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(xy), half(xy[::-1])
    return np.array(lower[:-1] + upper[:-1])


def polygon_margin(points: npt.ArrayLike, polygon: npt.ArrayLike) -> np.ndarray:
    """Signed distance [m] of ground points (..., 2 or 3) to one fixed convex CCW polygon (m, 2).

    Positive strictly inside, negative outside; a polygon with fewer than three vertices (point or segment)
    has no inside. Vectorised over the points; used for ZMP margins and static-equilibrium regions.
    """
    vertices = float_array(polygon, "polygon", last=2, min_ndim=2)
    if vertices.shape[0] < 1:
        raise ValueError("polygon must have at least one vertex")
    query = float_array(points, "points", min_ndim=1)
    if query.shape[-1] not in (2, 3):
        raise ValueError(f"points must have a last dimension of 2 or 3, got shape {query.shape}")
    p = query[..., None, :2]
    if len(vertices) == 1:
        return -np.linalg.norm(p[..., 0, :] - vertices[0], axis=-1)
    start, end = vertices, np.roll(vertices, -1, axis=0)
    direction, relative = end - start, p - start
    s = np.clip(np.sum(relative * direction, axis=-1) / np.sum(direction * direction, axis=-1), 0.0, 1.0)
    distance = np.min(np.linalg.norm(relative - s[..., None] * direction, axis=-1), axis=-1)
    cross = direction[:, 0] * relative[..., 1] - direction[:, 1] * relative[..., 0]
    inside = np.all(cross > 0.0, axis=-1) if len(vertices) >= 3 else np.zeros(distance.shape, dtype=bool)
    return np.where(inside, distance, -distance)


def support_polygon_centroid(contact_points: npt.ArrayLike, active: npt.ArrayLike | None = None) -> np.ndarray:
    """Area centroid (..., 2) [m] of the support polygon at every sample.

    For a line support (two or more collinear contacts) it is the midpoint of the segment, for a point
    support the point. This is the reference S of the paper's Stability Performance 1.
    """
    points, mask = _contacts(contact_points, active)
    x, y, flat_mask, shape = _flatten(points, mask)
    hull = _hull(x, y, flat_mask)
    # Shoelace over the hull edges, each counted once: drop slots spanning a collinear contact (their pieces
    # are slots too) and slots starting or ending at a duplicate of a lower-numbered contact.
    unique = _first_of_coincident(hull)
    primary = hull.valid & ~_spans_active_point(hull) & unique[hull.start_index] & unique[hull.end_index]
    ex, ey = hull.sx + hull.dx, hull.sy + hull.dy
    cross = np.where(primary, hull.sx * ey - ex * hull.sy, 0.0)
    area = 0.5 * np.sum(cross, axis=0)
    safe = 6.0 * np.where(area > 0.0, area, 1.0)
    centroid_x = np.sum((hull.sx + ex) * cross, axis=0) / safe
    centroid_y = np.sum((hull.sy + ey) * cross, axis=0) / safe
    # Degenerate supports: midpoint of the longest valid segment, or the (first) active point.
    longest = np.argmax(np.where(hull.valid, hull.length, -1.0), axis=0)
    columns = np.arange(x.shape[1])
    mid_x = hull.sx[longest, columns] + 0.5 * hull.dx[longest, columns]
    mid_y = hull.sy[longest, columns] + 0.5 * hull.dy[longest, columns]
    first = np.argmax(flat_mask, axis=0)
    extent = np.max(np.hypot(x - x[:1], y - y[:1]), axis=0)
    degenerate = area <= 1e-12 * (extent * extent + 1e-300)
    any_edge = hull.any_edge
    fallback_x = np.where(any_edge, mid_x, x[first, columns])
    fallback_y = np.where(any_edge, mid_y, y[first, columns])
    result = np.stack([np.where(degenerate, fallback_x, centroid_x), np.where(degenerate, fallback_y, centroid_y)], axis=-1)
    return result.reshape(shape + (2,))


def _spans_active_point(hull: _Hull) -> np.ndarray:
    """(E, T) whether an active contact lies strictly inside the segment of the slot (a collinear split)."""
    length_sq = hull.length * hull.length
    safe = np.where(length_sq > 0.0, length_sq, 1.0)
    spans = np.zeros(hull.valid.shape, dtype=bool)
    for other in range(hull.x.shape[0]):
        rx, ry = hull.x[other] - hull.sx, hull.y[other] - hull.sy
        s = (rx * hull.dx + ry * hull.dy) / safe
        on_line = np.abs(hull.dx * ry - hull.dy * rx) <= _HULL_TOLERANCE * 10 * (length_sq + 1e-300)
        spans |= on_line & (s > 1e-9) & (s < 1 - 1e-9) & hull.mask[other]
    return spans


def _first_of_coincident(hull: _Hull) -> np.ndarray:
    """(k, T) active contacts with no coincident active contact of lower index."""
    x, y, mask = hull.x, hull.y, hull.mask
    scale = np.max(np.hypot(x - x[:1], y - y[:1]), axis=0) + 1e-300
    first = mask.copy()
    for a in range(1, x.shape[0]):
        for b in range(a):
            first[a] &= ~((np.hypot(x[a] - x[b], y[a] - y[b]) <= 1e-12 * scale) & mask[b])
    return first
