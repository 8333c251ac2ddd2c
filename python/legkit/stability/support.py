"""Support polygon of the contacts and the static stability margin.

The support polygon is the convex hull of the ground projections (x, y) of the contact points; z is up.
Everything here is vectorised over leading sample dimensions: `contact_points` has shape (..., k, 3) and an
optional boolean `active` (..., k) selects the contacts touching the ground at each sample, so a gait whose
support set changes over time is one array call. Contacts closer than a tolerance tau (SUPPORT_TOLERANCE times
the support's diameter plus the rounding level of the coordinates plus 1e-13 m, see below) are merged first, so results do
not change when the scene is rotated or translated, and change continuously as contacts come together. For k contacts the
hull edges are found by testing all k (k - 1) ordered pairs at once: an ordered pair i -> j of distinct
contacts is a counter-clockwise hull edge when every other contact lies strictly to its left or on the
segment i-j itself (not on its extension), which is loop-free and cheap for the handful of feet a robot has.
Degenerate supports: when all contacts merge into one, the support is a point and has no edges; when they
are collinear it is a segment, whose two edges are the segment between the extreme contacts traversed both
ways (both sides of the line are outside).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from legkit._validation import bool_mask, float_array

# One tolerance tau, a distance [m] per sample, decides both which contacts are distinct and which are collinear:
#     tau = SUPPORT_TOLERANCE * D + _ROUNDING * M + _ABSOLUTE_TOLERANCE,
# D the support's diameter (largest distance between two active contacts' ground projections), M the largest
# |x| or |y| of the active contacts (so _ROUNDING * M is the rounding level of the coordinates: a rotation or
# translation of the scene moves them by a few eps * M), and an absolute floor of 1e-13 m, far below any
# physical contact spacing, so that a support of sub-atomic size is a point (its squared lengths would
# otherwise underflow).
# * Two active contacts closer than tau are one contact; the lowest-index member of each cluster is kept.
#   Without this, a pair a rounding error apart spans a hull "edge" whose direction is pure noise and changes
#   when the scene is rotated or translated.
# * A contact within tau of the line through two others lies on it, the distance being measured as the height
#   of their triangle over its longest side (symmetric in the three points, so the three edges of the triangle
#   agree, and well-conditioned even when two of the points are close): collinear contacts make one edge
#   between the extreme ones, never sub-edges.
# tau is kept near rounding level so that the polygon, and the margins measured to it, stay exact to ~1e-12 m.
SUPPORT_TOLERANCE = 1e-13
_ROUNDING = 64.0 * np.finfo(np.float64).eps
_ABSOLUTE_TOLERANCE = 1e-13  # [m]


@dataclass(frozen=True)
class SupportEdges:
    """Counter-clockwise support-polygon edges of every sample, one slot per ordered contact pair.

    start, end: (..., E, 2) edge end points in the ground plane, E = k (k - 1);
    valid: (..., E) whether the slot is a hull edge at that sample, after merging near-coincident contacts
    (module docstring); collinear contacts give one edge between the extreme ones; for a segment support
    both directions of the segment are edges (both sides of the line are "outside"), a point support has none;
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


#: The largest coordinate [m] the support geometry takes: its cross products square the coordinates, which beyond
#: about 1e150 overflow to NaN. 1e100 m is far beyond any robot and leaves the products room.
MAX_COORDINATE = 1e100


def _contacts(contact_points: npt.ArrayLike, active: npt.ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
    points = float_array(contact_points, "contact_points", last=3, min_ndim=2, bound=MAX_COORDINATE)
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
    mask: np.ndarray  # (k, T) active contacts left after merging near-coincident ones
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


def _distinct(
    x: np.ndarray, y: np.ndarray, mask: np.ndarray, tolerance: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Merge near-coincident active contacts (k, T) (see SUPPORT_TOLERANCE, or closer than an explicit
    `tolerance` [m]): returns the (k, T) mask of the contacts kept (the lowest-index member of every cluster)
    and the (T,) tolerance tau [m]."""
    k = x.shape[0]
    distance = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])  # (k, k, T)
    both = mask[:, None] & mask[None, :]
    diameter = np.max(np.where(both, distance, 0.0), axis=(0, 1))
    magnitude = np.max(np.where(mask, np.maximum(np.abs(x), np.abs(y)), 0.0), axis=0)
    if tolerance is None:
        tau = SUPPORT_TOLERANCE * diameter + _ROUNDING * magnitude + _ABSOLUTE_TOLERANCE
    else:
        tau = np.full(diameter.shape, tolerance)
    kept = mask.copy()
    for later in range(1, k):  # greedy in index order: k is the number of feet, vectorised over samples
        near = kept[:later] & (distance[:later, later] <= tau)
        kept[later] &= ~np.any(near, axis=0)
    return kept, tau


def _hull(x: np.ndarray, y: np.ndarray, mask: np.ndarray, tolerance: float | None = None) -> _Hull:
    """Ordered pairs i -> j of the merged active contacts (k, T) that are CCW hull edges (module docstring).

    The side test runs once per unordered pair: j -> i sees every point on the opposite side of i -> j
    (cross products negate), so both directions come from one pass. `tolerance` [m] replaces tau if given."""
    kept, tau = _distinct(x, y, mask, tolerance)
    k = x.shape[0]
    a, b = np.triu_indices(k, 1)
    sx, sy = x[a], y[a]
    dx, dy = x[b] - sx, y[b] - sy
    length_sq = dx * dx + dy * dy  # the end point's own `along` below, bit for bit
    length = np.sqrt(length_sq)
    both = kept[a] & kept[b]
    forward, backward = both.copy(), both
    for other in range(k):  # k is the number of feet: a handful; the work is vectorised over pairs and samples
        rx, ry = x[other] - sx, y[other] - sy
        cross = dx * ry - dy * rx
        # Height of the triangle (start, end, other) over its longest side: the same for all three of its edges.
        longest = np.maximum(length, np.maximum(np.hypot(rx, ry), np.hypot(x[other] - x[b], y[other] - y[b])))
        band = tau * longest
        along = dx * rx + dy * ry
        on_segment = (np.abs(cross) <= band) & (along >= 0.0) & (along <= length_sq)
        free = on_segment | ~kept[other]  # the end points themselves are on the segment
        forward &= (cross > band) | free
        backward &= (cross < -band) | free
    i, j = np.concatenate([a, b]), np.concatenate([b, a])
    return _Hull(
        x, y, kept, i, j,
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
    distance = np.where(any_edge, np.min(segment, axis=0, initial=np.inf), np.min(vertex, axis=0))  # one contact: no pairs
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
    point = float_array(com, "com", last=3, bound=MAX_COORDINATE)
    points, mask = _contacts(contact_points, active)
    shape = np.broadcast_shapes(point.shape[:-1], points.shape[:-2], mask.shape[:-1])
    points = np.broadcast_to(points, shape + points.shape[-2:])
    mask = np.broadcast_to(mask, shape + mask.shape[-1:])
    x, y, flat_mask, _ = _flatten(points, mask)
    flat_point = np.broadcast_to(point, shape + (3,)).reshape(-1, 3)
    return _signed_distance(flat_point[:, 0], flat_point[:, 1], _hull(x, y, flat_mask)).reshape(shape)


def support_polygon(contact_points: npt.ArrayLike, active: npt.ArrayLike | None = None) -> np.ndarray:
    """Counter-clockwise vertices (m, 2) [m] of the support polygon of one sample, starting at the lowest-x
    (then lowest-y) vertex.

    contact_points: (k, 3) world positions [m]; active: optional (k,) bool. Built from the same merged contacts
    and hull edges as `support_edges` (module docstring): only strict corners are vertices, so collinear
    contacts give the two end points (m = 2) and contacts that all merge give a single point (m = 1).
    """
    points, mask = _contacts(contact_points, active)
    if points.ndim != 2:
        raise ValueError(f"contact_points must be (k, 3) for one sample, got shape {points.shape}")
    x, y, flat_mask, _ = _flatten(points, mask)
    return _polygon(_hull(x, y, flat_mask))


def _polygon(hull: _Hull) -> np.ndarray:
    """CCW vertices (m, 2) of the hull of the first sample, from the lowest-x (then lowest-y) vertex."""
    if not hull.any_edge[0]:
        first = int(np.argmax(hull.mask[:, 0]))
        return np.array([[hull.x[first, 0], hull.y[first, 0]]])
    corners = np.unique(hull.start_index[hull.valid[:, 0]])
    xy = np.column_stack([hull.x[corners, 0], hull.y[corners, 0]])
    if len(xy) == 2:
        return xy[np.lexsort((xy[:, 1], xy[:, 0]))]
    # The corners of a convex polygon, sorted by angle about their mean, are in counter-clockwise order.
    centre = xy.mean(axis=0)
    ccw = xy[np.argsort(np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0]))]
    return np.roll(ccw, -int(np.lexsort((ccw[:, 1], ccw[:, 0]))[0]), axis=0)


def convex_hull_2d(xy: np.ndarray, tolerance: float) -> np.ndarray:
    """CCW corners (m, 2) of the hull of 2-D points (n, 2), built like the support polygon but with an explicit
    `tolerance` [m] instead of tau: points closer than it merge, and a point within it of a line through two
    others lies on that line. So a point farther than `tolerance` beyond every hull edge it lies outside of is
    always a corner (the iterative projection of `static_equilibrium_region` relies on this to terminate).
    """
    x, y = np.ascontiguousarray(xy[:, :1]), np.ascontiguousarray(xy[:, 1:2])
    return _polygon(_hull(x, y, np.ones(x.shape, dtype=bool), tolerance))


def distinct_contact_count(contact_points: npt.ArrayLike, active: npt.ArrayLike | None = None) -> np.ndarray:
    """Number (...,) of distinct active contacts at every sample, after merging contacts closer than the
    support tolerance (module docstring). S_H needs at least two (an edge to tip about).

    contact_points: (..., k, 3) world positions [m]; active: optional (..., k) bool.
    """
    points, mask = _contacts(contact_points, active)
    x, y, flat_mask, shape = _flatten(points, mask)
    kept, _ = _distinct(x, y, flat_mask)
    return np.sum(kept, axis=0).reshape(shape)


def polygon_margin(points: npt.ArrayLike, polygon: npt.ArrayLike) -> np.ndarray:
    """Signed distance [m] of ground points (..., 2 or 3) to one fixed convex CCW polygon (m, 2).

    Positive strictly inside, negative outside; a polygon with fewer than three vertices (point or segment)
    has no inside. Vectorised over the points; used for ZMP margins and static-equilibrium regions.
    """
    vertices = float_array(polygon, "polygon", last=2, min_ndim=2, bound=MAX_COORDINATE)
    if vertices.shape[0] < 1:
        raise ValueError("polygon must have at least one vertex")
    distinct = np.any(vertices != np.roll(vertices, -1, axis=0), axis=1)  # a repeated vertex makes no edge
    vertices = vertices[distinct] if np.any(distinct) else vertices[:1]
    query = float_array(points, "points", min_ndim=1, bound=MAX_COORDINATE)
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
    support (all contacts merged, module docstring) the first active contact. This is the reference S of the paper's Stability Performance 1.
    """
    points, mask = _contacts(contact_points, active)
    x, y, flat_mask, shape = _flatten(points, mask)
    hull = _hull(x, y, flat_mask)
    # Shoelace over the hull edges: each is one slot, as contacts are merged and collinear ones make one edge.
    ex, ey = hull.sx + hull.dx, hull.sy + hull.dy
    cross = np.where(hull.valid, hull.sx * ey - ex * hull.sy, 0.0)
    area = 0.5 * np.sum(cross, axis=0)
    safe = 6.0 * np.where(area > 0.0, area, 1.0)
    centroid_x = np.sum((hull.sx + ex) * cross, axis=0) / safe
    centroid_y = np.sum((hull.sy + ey) * cross, axis=0) / safe
    # Degenerate supports, as the hull classifies them: a segment (its edge valid both ways) gives its
    # midpoint, a point (no edge) the first active contact.
    pairs = hull.valid.shape[0] // 2
    two_sided = hull.valid[:pairs] & hull.valid[pairs:]
    segment = np.argmax(two_sided, axis=0)
    columns = np.arange(x.shape[1])
    mid_x = hull.sx[segment, columns] + 0.5 * hull.dx[segment, columns]
    mid_y = hull.sy[segment, columns] + 0.5 * hull.dy[segment, columns]
    first = np.argmax(hull.mask, axis=0)
    degenerate = np.any(two_sided, axis=0) | ~hull.any_edge
    fallback_x = np.where(hull.any_edge, mid_x, x[first, columns])
    fallback_y = np.where(hull.any_edge, mid_y, y[first, columns])
    result = np.stack([np.where(degenerate, fallback_x, centroid_x), np.where(degenerate, fallback_y, centroid_y)], axis=-1)
    return result.reshape(shape + (2,))
