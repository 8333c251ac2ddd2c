"""Static equilibrium with friction for several contacts (after Bretl & Lall, 2008).

A rigid robot of mass m (set to 1: the region does not depend on it) rests on point contacts r_i with unit
normals n_i. It is in static equilibrium with its COM at c iff contact forces f_i inside the friction cones
balance gravity:

    sum f_i = m g e_z,      sum r_i x f_i + c x (-m g e_z) = 0,      f_i in cone(n_i, mu).

The moment equation involves only c_x and c_y, so the COM positions that can be balanced form a vertical
prism over a convex polygon: the projection onto (c_x, c_y) of the polytope of (f, c_x, c_y). Each cone is
linearised by an inscribed pyramid with `cone_sides` faces (mu cos(pi / sides) at the face centres), so the
region is a certified inner approximation that grows with both mu and sides.

The polygon is found by iterative projection: support points (LP maxima of d . c) in three directions
give a triangle; each edge's outward normal is then tried as a new direction, and the new support point is
inserted if it lies beyond the edge, until no edge moves by more than `tolerance`. The projection of a
polytope is a polygon, so this ends with every edge confirmed by an LP. LPs use scipy's HiGHS.

For coplanar horizontal contacts the region is the support polygon, whatever mu >= 0 (vertical forces
suffice); friction only matters for contacts on slopes, steps and walls.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
import numpy.typing as npt
from scipy.optimize import OptimizeResult, linprog

import legkit as lk
from legkit._validation import float_array, friction_coefficient, integer, positive_scalar, unit_vectors
from legkit.stability.support import convex_hull_2d, polygon_margin


def _contact_arrays(contacts: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]]) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(contacts, np.ndarray) or not isinstance(contacts, Sequence):
        raise TypeError("contacts must be a sequence of (point, unit normal) pairs")
    if len(contacts) < 1:
        raise ValueError("contacts must hold at least one (point, normal) pair")
    for entry in contacts:
        if not isinstance(entry, (tuple, list)) or len(entry) != 2:
            raise TypeError(f"each contact must be a (point, normal) pair, got {entry!r}")
    # A list of array-likes is array-like; numpy's stubs cannot say so.
    points = float_array(cast(npt.ArrayLike, [p for p, _ in contacts]), "contacts (points)", last=3)
    normals = unit_vectors(cast(npt.ArrayLike, [n for _, n in contacts]), "contacts (normals)")
    return points.reshape(-1, 3), normals.reshape(-1, 3)


def _tangent_basis(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(normals[:, [0]]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    return t1, np.cross(normals, t1)


class _EquilibriumLP:
    """Constraint matrices of the equilibrium polytope in x = (f_1, ..., f_k, c_x, c_y), mass 1."""

    def __init__(self, points: np.ndarray, normals: np.ndarray, mu: float, cone_sides: int, bound: float):
        k = len(points)
        self.k = k
        weight = lk.STANDARD_GRAVITY  # any g > 0 along -z gives the same region (the forces scale with it)
        # Equalities: force balance (3 rows), moment balance (3 rows); c x (-w e_z) = (-w c_y, w c_x, 0).
        a_eq = np.zeros((6, 3 * k + 2))
        for i, r in enumerate(points):
            a_eq[0:3, 3 * i : 3 * i + 3] = np.eye(3)
            a_eq[3:6, 3 * i : 3 * i + 3] = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        a_eq[3, 3 * k + 1] = -weight
        a_eq[4, 3 * k] = weight
        self.a_eq = a_eq
        self.b_eq = np.array([0.0, 0.0, weight, 0.0, 0.0, 0.0])
        # Inscribed pyramid: f . (cos t_j u + sin t_j w) <= mu cos(pi/sides) f . n for every face j.
        t1, t2 = _tangent_basis(normals)
        angles = 2.0 * np.pi * np.arange(cone_sides) / cone_sides
        reach = mu * np.cos(np.pi / cone_sides)
        rows = []
        for i in range(k):
            for angle in angles:
                row = np.zeros(3 * k + 2)
                row[3 * i : 3 * i + 3] = np.cos(angle) * t1[i] + np.sin(angle) * t2[i] - reach * normals[i]
                rows.append(row)
            row = np.zeros(3 * k + 2)
            row[3 * i : 3 * i + 3] = -normals[i]  # unilateral: f . n >= 0 (needed when mu = 0)
            rows.append(row)
        self.a_ub = np.array(rows)
        self.b_ub = np.zeros(len(rows))
        centre = points[:, :2].mean(axis=0)
        self.bounds = [(None, None)] * (3 * k) + [(centre[0] - bound, centre[0] + bound), (centre[1] - bound, centre[1] + bound)]

    def _solve(self, cost: np.ndarray, bounds: list) -> OptimizeResult:
        """HiGHS' dual simplex, then its interior-point method when the simplex ends without a verdict
        (it occasionally stops with an unknown model status on these small, degenerate LPs)."""
        for method in ("highs-ds", "highs-ipm"):
            result = linprog(cost, A_ub=self.a_ub, b_ub=self.b_ub, A_eq=self.a_eq, b_eq=self.b_eq, bounds=bounds, method=method)
            if result.status in (0, 2):
                return result
        raise RuntimeError(f"HiGHS failed on the equilibrium LP: {result.message}")

    def support(self, direction: np.ndarray) -> np.ndarray | None:
        """The COM ground point maximising direction . c, or None when no equilibrium exists at all."""
        cost = np.zeros(3 * self.k + 2)
        cost[-2:] = -direction
        result = self._solve(cost, self.bounds)
        return None if result.status == 2 else result.x[-2:]

    def feasible_at(self, com_xy: np.ndarray) -> bool:
        bounds = self.bounds[:-2] + [(com_xy[0], com_xy[0]), (com_xy[1], com_xy[1])]
        return self._solve(np.zeros(3 * self.k + 2), bounds).status == 0


#: The most faces a friction pyramid takes: the LP has one variable per face and contact, and at 1000 faces the
#: pyramid already reaches mu cos(pi / 1000), within 5e-6 of the cone.
MAX_CONE_SIDES = 1000


def _check(
    contacts: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]], mu: float, cone_sides: int
) -> tuple[np.ndarray, np.ndarray, float, int]:
    points, normals = _contact_arrays(contacts)
    friction = friction_coefficient(mu)
    if friction.ndim != 0:
        raise ValueError(f"mu must be a scalar, got shape {friction.shape}")
    sides = integer(cone_sides, "cone_sides")
    if not 3 <= sides <= MAX_CONE_SIDES:
        raise ValueError(f"cone_sides must be in [3, {MAX_CONE_SIDES}], got {cone_sides}")
    return points, normals, float(friction), sides


def static_equilibrium_region(
    contacts: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]],
    mu: float,
    cone_sides: int = 8,
    tolerance: float = 1e-9,
    bound: float = 100.0,
) -> np.ndarray:
    """Counter-clockwise vertices (m, 2) [m] of the region of COM ground positions in static equilibrium.

    contacts: sequence of (point (3,), unit normal (3,)) pairs, world frame, normals into the robot;
    mu >= 0: friction coefficient; cone_sides >= 3 faces of the inscribed friction pyramid; tolerance [m]:
    an edge is final when no support point lies farther than this beyond it; bound [m]: the search is
    clipped to a square of half-size `bound` around the contacts' mean, so regions that are unbounded (e.g.
    between two opposing walls) come back clipped. Returns an empty (0, 2) array when no COM position can be
    balanced, (1, 2) or (2, 2) for a point or segment region.
    """
    points, normals, friction, sides = _check(contacts, mu, cone_sides)
    tol = positive_scalar(tolerance, "tolerance")
    lp = _EquilibriumLP(points, normals, friction, sides, positive_scalar(bound, "bound"))
    found = []
    for angle in (0.5 * np.pi, 0.5 * np.pi + 2.0 * np.pi / 3.0, 0.5 * np.pi + 4.0 * np.pi / 3.0):
        point = lp.support(np.array([np.cos(angle), np.sin(angle)]))
        if point is None:
            return np.zeros((0, 2))
        found.append(point)
    polygon = convex_hull_2d(np.array(found), tol)
    confirmed: set[tuple[tuple[float, float], tuple[float, float]]] = set()
    while True:
        if len(polygon) < 3:
            # A point or segment so far: probe both normals of the segment (and its direction) once.
            extra = _probe_degenerate(lp, polygon)
            merged = convex_hull_2d(np.vstack([polygon, extra]), tol)
            if len(merged) == len(polygon):
                return polygon
            polygon = merged
            continue
        grew = False
        for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
            key = (tuple(a), tuple(b))
            if key in confirmed:
                continue
            edge = b - a
            normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
            point = lp.support(normal)
            if point is not None and normal @ (point - a) > tol:
                polygon = convex_hull_2d(np.vstack([polygon, point]), tol)
                grew = True
                break
            confirmed.add(key)
        if not grew:
            return polygon


def _probe_degenerate(lp: _EquilibriumLP, polygon: np.ndarray) -> np.ndarray:
    if len(polygon) == 2:
        edge = polygon[1] - polygon[0]
        normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        directions = [normal, -normal]
    else:
        directions = [np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([-1.0, 0.0]), np.array([0.0, -1.0])]
    return np.array([p for p in (lp.support(d) for d in directions) if p is not None]).reshape(-1, 2)


def is_statically_stable(
    com: npt.ArrayLike,
    contacts: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]],
    mu: float,
    cone_sides: int = 8,
) -> np.ndarray | bool:
    """Whether gravity at COM position(s) com (3,) or (..., 3) [m] can be balanced by contact forces inside
    the linearised friction cones of `contacts` ((point, unit normal) pairs), with friction coefficient mu.

    A single COM is decided by one feasibility LP (exact up to the solver's 1e-9 tolerance); a batch is
    tested against `static_equilibrium_region` (computed once), so a trajectory costs one region. COMs on the
    region's boundary count as stable.
    """
    position = float_array(com, "com", last=3)
    points, normals, friction, sides = _check(contacts, mu, cone_sides)
    if position.ndim == 1:
        lp = _EquilibriumLP(points, normals, friction, sides, bound=np.inf)
        return lp.feasible_at(position[:2])
    region = static_equilibrium_region(contacts, friction, sides)
    if len(region) == 0:
        return np.zeros(position.shape[:-1], dtype=bool)
    return polygon_margin(position, region) >= -1e-9


def static_equilibrium_margin(
    com: npt.ArrayLike,
    contacts: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]],
    mu: float,
    cone_sides: int = 8,
) -> np.ndarray:
    """Signed distance (...,) [m] from the COM ground projection(s) to the boundary of the static-equilibrium
    region: positive inside (stable), negative outside. Raises ValueError when the region is empty."""
    position = float_array(com, "com", last=3)
    region = static_equilibrium_region(contacts, mu, cone_sides)
    if len(region) == 0:
        raise ValueError("no COM position can be balanced on these contacts with this mu: the region is empty")
    return polygon_margin(position, region)
