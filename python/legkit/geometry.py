"""Circle–line distance in 3D, and the joint question built on it: which rotation about an axis brings a
point closest to a line (Moll et al., IROS 2006, §IV). The kernels (and the broadcasting
of batch dimensions) are in Rust; this module shapes the results."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from legkit import _core


@dataclass(frozen=True)
class CircleLineResult:
    """Closest points between a circle and a line.

    For a single query: ``distance`` is a float, ``circle_points`` and ``line_points`` are ``(k, 3)`` with
    ``k = count`` in {1, 2} (two when two circle points tie), and ``equidistant`` is a bool: True when every
    circle point is equally far from the line (the line is the circle's axis, or the radius is 0); then
    ``count == 1`` and the point given is one representative.

    For a batch with leading shape ``B``: ``distance`` is ``B``, ``count`` and ``equidistant`` are ``B``
    arrays, and the point arrays are ``B + (2, 3)`` whose second row repeats the first where ``count == 1``.
    """

    distance: Any
    circle_points: np.ndarray
    line_points: np.ndarray
    count: Any
    equidistant: Any


def circle_line(center: Any, normal: Any, radius: Any, line_point: Any, line_direction: Any) -> CircleLineResult:
    """Minimum distance between the circle (``center``, ``normal``, ``radius``) and the infinite line through
    ``line_point`` along ``line_direction``.

    ``normal`` and ``line_direction`` must be non-zero (they are normalised); ``radius`` must be >= 0.
    Every argument may carry leading batch dimensions; they broadcast against each other.
    Accurate to ~1e-15 of the scene's size (radius plus the centre's distance from the line), in every
    degenerate configuration too; about 90 ns per query.
    """
    distance, count, circle_points, line_points, equidistant = _core.circle_line(
        center, normal, radius, line_point, line_direction
    )
    if distance.ndim == 0:
        k = int(count)
        return CircleLineResult(float(distance), circle_points[:k], line_points[:k], k, bool(equidistant))
    return CircleLineResult(distance, circle_points, line_points, count, equidistant)


def rotation_toward_line(
    axis_point: Any, axis_direction: Any, point: Any, line_point: Any, line_direction: Any
) -> tuple[Any, Any]:
    """The angle ``theta`` (radians, right-handed about ``axis_direction``, in (-pi, pi]) that rotates
    ``point`` about the axis through ``axis_point`` to be closest to the line, and that distance.

    ``theta`` is 0 when the point lies on the axis or the axis is the line (every angle is equally good).
    When two angles tie, the one that leaves the rotated point lowest (smallest z) is returned.
    Leading batch dimensions broadcast; a batch returns two arrays.
    """
    theta, distance = _core.rotation_toward_line(axis_point, axis_direction, point, line_point, line_direction)
    if theta.ndim == 0:
        return float(theta), float(distance)
    return theta, distance
