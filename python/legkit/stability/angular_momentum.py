"""The paper's Stability Performance 2: the angular-momentum stability index S_H.

[Hardt 2002, Sect. 3.2, eq. 10 and the diagonal-edge cases after it]. S_H(t) = min over the support edges l
of S_H^l(t) (eq. 10); positive is stable. Two definitions are offered, ``definition="paper"`` (the default)
and ``definition="energy"``.

Shared geometry. Every edge is a horizontal axis through its start contact p with a horizontal unit normal n
pointing to the side the robot would tip to, and the unit vector e_l = z x n along the edge. With c the COM:

* r_l,CM = (c - p) minus its component along e_l: the orthogonal vector from the edge to the COM; r = |r_l,CM|,
  h its vertical component, d = -n . r_l,CM the horizontal distance of the ground-projected COM (GCoM) inside
  the edge (d < 0: beyond it).
* H = H_p . e_l = e_l . (k_G + (c - p) x P) [N m s]: the angular momentum about the edge (k_G centroidal
  angular momentum, P linear momentum). H > 0 tips the robot over the edge, toward n.

definition="paper": the published index, literally
---------------------------------------------------
* H_ref = (r_l,CM x m v_ref) . e_l, v_ref the velocity whose kinetic energy m |v_ref|^2 / 2 raises the COM to
  "the higher potential energy at which the system CoM would lie above edge l", m g (r - h), directed to tip
  over the edge (perpendicular to r_l,CM and e_l): H_ref = m r sqrt(2 g (r - h)), an inverted pendulum with
  all the mass at the COM.
* H_max = (r_l,CM x m v_tip_max) . e_l with |v_tip_max| the swing-leg tip speed, in the same direction:
  H_max = m r v_tip_max.
* An edge is *diagonal* when it joins diagonally opposed legs: the contact pairs in ``diagonal_pairs``.
  "Before", "past", "behind" and "in front" are along the direction of travel ``direction`` (+x by default).
* Edges and their side n. A support of three or more contacts has its polygon's edges, n pointing out of the
  polygon. "Two legs in contact" span a segment, the polygon's one edge: a non-diagonal pair is tipped over
  away from the GCoM (n points away from it), a diagonal pair forward (n along the direction of travel).
* S_H^l per edge:

      non-diagonal                                     H_ref - H
      diagonal, two legs, GCoM before the edge         min(H - H_ref, H_max - H)
      diagonal, two legs, GCoM past the edge           H_max - H
      diagonal, third support leg behind the edge      H_max - H        (the edge is the front of the support)
      diagonal, third support leg in front             H_ref - H        (the edge is its rear)

  "GCoM before the edge" is d > 0 for the forward-facing side: the COM has not yet rolled over the diagonal
  and needs H >= H_ref to do so, the situation of the paper's Fig. 3 after each switch to a diagonal pair.
  The published cases are discontinuous where the GCoM crosses a diagonal edge: H_ref is 0 there, and S_H^l
  jumps from min(H, H_max - H) to H_max - H (the jump in ``legkit gait``'s plot halfway through each diagonal
  phase).

definition="energy": legkit's energy-consistent variant
--------------------------------------------------------
The published index has three properties that make it a poor margin outside the paper's optimised amble:
its H_ref ignores the rotational inertia of the body (the kinetic energy of a body turning about the edge is
H^2 / (2 I_e), not (H / r)^2 / (2 m)); its H_max is a momentum the swing leg does not bound; and with the COM
beyond a non-diagonal edge, H_ref - H stays positive at rest, so S_H does not change sign when the COM leaves
the support polygon. The energy variant keeps H and the idea of the four cases, and changes:

* I_e = e_l^T I_G e_l + m r^2, the moment of inertia about the edge; H_ref = sqrt(2 I_e m g (r - h)), the
  angular momentum whose kinetic energy H^2 / (2 I_e) just raises the COM over the edge (equal to the paper's
  for a point mass, larger otherwise).
* H_max = I_e v_tip_max / l: the largest tipping momentum a swing leg can still catch. Its tip, at distance l
  from the edge axis, moves at omega l while the body tips at omega = H / I_e; l is the largest such distance
  among the swing tips beyond the edge.
* Every polygon edge is tipped over outward, and a segment on both sides (both are outside). An edge side is
  *diagonal* when a swing tip (``swing_tips``) lies beyond it, so the cases need no direction of travel and
  S_H is invariant to rotations about z; otherwise non-diagonal.

      non-diagonal   d >= 0:  S = H_ref - H              (the paper's case)
                     d <  0:  S = -H_ref - H             (the COM is beyond: only a return with H <= -H_ref
                                                          saves it)
      diagonal  (1)  d >= 0, H <= H_ref:   S = H_max + H_ref - H          (turns back before the edge)
                (2)  d >= 0, H >  H_ref:   S = H_max - sqrt(H^2 - H_ref^2) (passes the edge; the swing leg
                                                                           absorbs the residual momentum)
                (3)  d <  0, H >= -H_ref:  S = H_max - |H|                (leaning over the edge: falls, or
                                                                           turns and falls back through
                                                                           this pose with |H|)
                (4)  d <  0, H <  -H_ref:  S = H_max + sqrt(H^2 - H_ref^2) (swings back over the edge, away)

  Quasi-statically (H = 0) a non-diagonal edge gives S = sign(d) H_ref, so S_H changes sign exactly where the
  COM crosses a polygon edge. Cases (1)-(4) agree where they meet except across the separatrix H = -H_ref of
  (3)/(4), where the motion really does bifurcate (fall back or swing over).

The paper's index depends on the direction of travel (rotate a scene about z and its value changes unless
``direction`` turns with it); both are invariant to translations.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import bool_mask, float_array, positive_scalar
from legkit.stability.support import _contacts, _hull

Definition = Literal["paper", "energy"]
DEFINITIONS: tuple[str, ...] = ("paper", "energy")
DEFAULT_DIRECTION = (1.0, 0.0, 0.0)


def angular_momentum_stability(
    com: npt.ArrayLike,
    linear_momentum: npt.ArrayLike,
    angular_momentum: npt.ArrayLike,
    inertia: npt.ArrayLike | None,
    mass: float,
    contact_points: npt.ArrayLike,
    active: npt.ArrayLike | None = None,
    swing_tips: npt.ArrayLike | None = None,
    swing_active: npt.ArrayLike | None = None,
    v_tip_max: float | None = None,
    gravity: float = lk.STANDARD_GRAVITY,
    *,
    definition: Definition = "paper",
    direction: npt.ArrayLike | None = None,
    diagonal_pairs: npt.ArrayLike | None = None,
) -> np.ndarray:
    """S_H [Hardt 2002, eq. 10], (...,) [N m s]: the minimum over the support edges of S_H^l (module docstring).

    com: (..., 3) [m]; linear_momentum: (..., 3) [kg m/s]; angular_momentum: (..., 3) about the COM [N m s]
    (both as `lk.centroidal_momentum`); mass [kg]; contact_points: (..., k, 3) with optional active (..., k)
    bool (at least two distinct active contacts per sample, an edge to tip about: contacts closer than the
    support tolerance merge, see `legkit.stability.support` and `distinct_contact_count`); v_tip_max: the
    swing-leg tip speed [m/s]; gravity: magnitude [m/s^2] of a gravity pointing along -z.

    definition="paper" (default): the published index. diagonal_pairs: (p, 2) contact indices whose edges are
    diagonal (v_tip_max is then required); direction: (3,) direction of travel, only its horizontal part
    counts (default +x). inertia is not used (may be None); swing_tips must not be given.
    definition="energy": inertia: (..., 3, 3) about the COM, world frame [kg m^2]; swing_tips: optional
    (..., s, 3) tips of legs in the air with optional swing_active (..., s) bool, which make the edges they
    lie beyond diagonal; v_tip_max is required with swing_tips; direction and diagonal_pairs must not be given.
    """
    return np.min(
        _edge_indices(
            com, linear_momentum, angular_momentum, inertia, mass, contact_points, active, swing_tips, swing_active,
            v_tip_max, gravity, definition, direction, diagonal_pairs,
        ),
        axis=-1,
    )


@dataclass(frozen=True)
class _Edges:
    """Every support edge of every sample as flat (V,) vectors (module docstring's names), n outward of the
    polygon (to the right of its CCW direction)."""

    edge: np.ndarray  # slot of each edge in the (E, T) hull layout
    sample: np.ndarray  # flat sample of each edge
    start_index: np.ndarray  # contact indices of the edge's ends
    end_index: np.ndarray
    nx: np.ndarray
    ny: np.ndarray
    start: np.ndarray  # (3, V) the edge's start contact
    offset: np.ndarray  # (3, V) c - p
    d: np.ndarray
    r: np.ndarray
    rise: np.ndarray  # r - h
    momentum: np.ndarray  # H
    segment: np.ndarray  # bool: the sample's support is a segment (two legs in contact)


def _edge_indices(
    com: npt.ArrayLike, linear_momentum: npt.ArrayLike, angular_momentum: npt.ArrayLike, inertia: npt.ArrayLike | None,
    mass: float, contact_points: npt.ArrayLike, active: npt.ArrayLike | None, swing_tips: npt.ArrayLike | None,
    swing_active: npt.ArrayLike | None, v_tip_max: float | None, gravity: float, definition: Definition,
    direction: npt.ArrayLike | None, diagonal_pairs: npt.ArrayLike | None,
) -> np.ndarray:
    """(..., E) S_H^l per edge slot, +inf in slots that are not edges (or, for the paper's two-leg segments,
    the side not tipped over). Computed component by component in an (E, T) layout: e_l is horizontal, so
    every product reduces to x/y terms."""
    if definition not in DEFINITIONS:
        raise ValueError(f"definition must be one of {DEFINITIONS}, got {definition!r}")
    c = float_array(com, "com", last=3)
    momentum = float_array(linear_momentum, "linear_momentum", last=3)
    k_g = float_array(angular_momentum, "angular_momentum", last=3)
    m = positive_scalar(mass, "mass")
    g = positive_scalar(gravity, "gravity")
    points, mask = _contacts(contact_points, active)
    shape = np.broadcast_shapes(c.shape[:-1], momentum.shape[:-1], k_g.shape[:-1], points.shape[:-2], mask.shape[:-1])
    if definition == "energy":
        if direction is not None or diagonal_pairs is not None:
            raise ValueError("direction and diagonal_pairs belong to definition='paper'; the energy variant finds "
                             "diagonal edges from swing_tips and needs no direction")
        if inertia is None:
            raise ValueError("inertia is required by definition='energy'")
        inertia_g = float_array(inertia, "inertia", min_ndim=2)
        if inertia_g.shape[-2:] != (3, 3):
            raise ValueError(f"inertia must have trailing shape (3, 3), got {inertia_g.shape}")
        shape = np.broadcast_shapes(shape, inertia_g.shape[:-2])
        if swing_tips is not None and v_tip_max is None:
            raise ValueError("v_tip_max is required when swing_tips is given")
    elif swing_tips is not None or swing_active is not None:
        raise ValueError("swing_tips and swing_active belong to definition='energy'; definition='paper' takes "
                         "its diagonal edges from diagonal_pairs")

    def flat(a: np.ndarray, trailing: tuple[int, ...]) -> np.ndarray:
        """(..., *trailing) -> (*trailing, T): sample axis last."""
        a = np.broadcast_to(a, shape + trailing).reshape((-1,) + trailing)
        return np.ascontiguousarray(np.moveaxis(a, 0, -1))

    pts = flat(points, points.shape[-2:])  # (k, 3, T)
    hull = _hull(pts[:, 0], pts[:, 1], flat(mask, mask.shape[-1:]))
    if not np.all(hull.any_edge):
        first = np.unravel_index(int(np.argmin(hull.any_edge)), shape) if shape else ()
        raise ValueError(
            f"contact_points: S_H needs at least two distinct active contacts (an edge to tip about); sample "
            f"{tuple(int(i) for i in first)} has a single support point"
        )
    # Work only on the slots that are edges (a few of the k (k - 1) per sample), gathered as flat vectors.
    edge, sample = np.nonzero(hull.valid)
    cc, pp, kk = flat(c, (3,))[:, sample], flat(momentum, (3,))[:, sample], flat(k_g, (3,))[:, sample]
    length = hull.length[edge, sample]
    nx, ny = hull.dy[edge, sample] / length, -hull.dx[edge, sample] / length
    ax, ay = -ny, nx  # e_l = z x n
    start = pts[hull.start_index[edge], :, sample].T  # (3, V)
    ox, oy, oz = cc[0] - start[0], cc[1] - start[1], cc[2] - start[2]
    d = -(nx * ox + ny * oy)  # r_l,CM = -d n + oz z
    r = np.sqrt(d * d + oz * oz)
    # Rise of the COM to above the edge, r - oz, written as d^2 / (r + oz) when oz > 0 to avoid cancellation.
    rise = np.where(oz > 0.0, d * d / np.where(oz > 0.0, r + oz, 1.0), r - oz)
    h_edge = ax * (kk[0] + oy * pp[2] - oz * pp[1]) + ay * (kk[1] + oz * pp[0] - ox * pp[2])
    edges = _Edges(
        edge, sample, hull.start_index[edge], hull.end_index[edge], nx, ny, start, np.stack([ox, oy, oz]), d, r,
        rise, h_edge, np.sum(hull.valid, axis=0)[sample] == 2,
    )
    if definition == "paper":
        value = _paper(edges, m, g, v_tip_max, direction, diagonal_pairs, points.shape[-2], shape)
    else:
        value = _energy(edges, flat(inertia_g, (3, 3))[:, :, sample], m, g, swing_tips, swing_active, v_tip_max, shape, flat)
    index: np.ndarray = np.full(hull.valid.shape, np.inf)  # (E, T); slots that are not edges stay +inf
    index[edge, sample] = value
    return np.moveaxis(index, -1, 0).reshape(shape + (index.shape[0],))


def _travel(direction: npt.ArrayLike | None) -> tuple[float, float]:
    """Unit horizontal direction of travel from a (3,) vector (default +x)."""
    vector = float_array(DEFAULT_DIRECTION if direction is None else direction, "direction")
    if vector.shape != (3,):
        raise ValueError(f"direction must be a 3-vector, got shape {vector.shape}")
    horizontal = float(np.hypot(vector[0], vector[1]))
    if horizontal == 0.0:
        raise ValueError(f"direction must have a horizontal component (travel along the ground), got {vector}")
    return float(vector[0]) / horizontal, float(vector[1]) / horizontal


def _pair_table(diagonal_pairs: npt.ArrayLike | None, contacts: int) -> np.ndarray:
    """(k, k) bool: which contact pairs are diagonal (symmetric)."""
    table = np.zeros((contacts, contacts), dtype=bool)
    if diagonal_pairs is None:
        return table
    pairs = np.asarray(diagonal_pairs)
    if pairs.size and not np.issubdtype(pairs.dtype, np.integer):
        raise TypeError(f"diagonal_pairs must hold contact indices (integers), got dtype {pairs.dtype}")
    pairs = pairs.reshape(-1, 2) if pairs.size else np.zeros((0, 2), dtype=int)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= contacts or np.any(pairs[:, 0] == pairs[:, 1])):
        raise ValueError(f"diagonal_pairs must pair two different contact indices in [0, {contacts}), got {pairs.tolist()}")
    table[pairs[:, 0], pairs[:, 1]] = table[pairs[:, 1], pairs[:, 0]] = True
    return table


def _paper(edges: _Edges, m: float, g: float, v_tip_max: float | None, direction: npt.ArrayLike | None,
           diagonal_pairs: npt.ArrayLike | None, contacts: int, shape: tuple[int, ...]) -> np.ndarray:
    """S_H^l of definition="paper" per edge (module docstring), +inf on the side of a segment not tipped over."""
    tx, ty = _travel(direction)
    diagonal = _pair_table(diagonal_pairs, contacts)[edges.start_index, edges.end_index]
    if np.any(diagonal) or v_tip_max is not None:
        if v_tip_max is None:
            raise ValueError("v_tip_max is required when diagonal_pairs name an edge of the support")
        speed = positive_scalar(v_tip_max, "v_tip_max")
    else:
        speed = 0.0
    forward = edges.nx * tx + edges.ny * ty  # > 0: this side of the edge faces the direction of travel
    ambiguous = diagonal & (forward == 0.0)
    if np.any(ambiguous):
        where = np.unravel_index(int(edges.sample[np.argmax(ambiguous)]), shape) if shape else ()
        raise ValueError(f"direction is parallel to a diagonal support edge at sample {tuple(int(i) for i in where)}: "
                         "'before' and 'behind' are undefined there")
    h_ref = m * edges.r * np.sqrt(2.0 * g * edges.rise)
    h_max = m * edges.r * speed
    h = edges.momentum
    before = edges.d > 0.0  # on the forward-facing side: the GCoM has not reached the edge yet
    two_legs = np.where(before, np.minimum(h - h_ref, h_max - h), h_max - h)
    polygon = np.where(forward > 0.0, h_max - h, h_ref - h)  # third leg behind (edge at the front) or in front
    value = np.where(diagonal, np.where(edges.segment, two_legs, polygon), h_ref - h)
    # A segment is one edge: a diagonal pair is tipped over forward, any other pair away from the GCoM (on the
    # line itself both sides count).
    other_side = edges.segment & np.where(diagonal, forward < 0.0, edges.d < 0.0)
    return np.where(other_side, np.inf, value)


def _energy(edges: _Edges, inertia: np.ndarray, m: float, g: float, swing_tips: npt.ArrayLike | None,
            swing_active: npt.ArrayLike | None, v_tip_max: float | None, shape: tuple[int, ...],
            flat: Callable[[np.ndarray, tuple[int, ...]], np.ndarray]) -> np.ndarray:
    """S_H^l of definition="energy" per edge (module docstring)."""
    ax, ay = -edges.ny, edges.nx
    inertia_edge = inertia[0, 0] * ax * ax + 2.0 * inertia[0, 1] * ax * ay + inertia[1, 1] * ay * ay + m * edges.r**2
    h_ref = np.sqrt(2.0 * inertia_edge * m * g * edges.rise)
    h = edges.momentum
    inside = edges.d >= 0.0
    value = np.where(inside, h_ref - h, -h_ref - h)
    if swing_tips is None:
        return value
    tips = float_array(swing_tips, "swing_tips", last=3, min_ndim=2)
    speed = positive_scalar(v_tip_max, "v_tip_max")
    tip_shape = np.broadcast_shapes(shape, tips.shape[:-2]) + tips.shape[-2:-1]
    tip_mask = flat(bool_mask(swing_active, "swing_active", tip_shape), tips.shape[-2:-1])[:, edges.sample]
    tips = flat(tips, tips.shape[-2:])[:, :, edges.sample]  # (s, 3, V)
    lever_sq = np.zeros_like(h)
    for tip in range(tips.shape[0]):  # a few swing feet; vectorised over edges and samples
        relative = tips[tip] - edges.start
        out = edges.nx * relative[0] + edges.ny * relative[1]  # beyond the edge if > 0
        lever_sq = np.where((out > 0.0) & tip_mask[tip], np.maximum(lever_sq, out * out + relative[2] ** 2), lever_sq)
    lever = np.sqrt(lever_sq)
    diagonal = lever > 0.0
    h_max = inertia_edge * speed / np.where(diagonal, lever, 1.0)
    residual = np.sqrt(np.maximum(h * h - h_ref * h_ref, 0.0))
    caught = h_max + np.where(
        inside,
        np.where(h <= h_ref, h_ref - h, -residual),  # cases (1), (2)
        np.where(h >= -h_ref, -np.abs(h), residual),  # cases (3), (4)
    )
    return np.where(diagonal, caught, value)


def angular_momentum_stability_of_model(
    model: lk.Model,
    q: npt.ArrayLike,
    v: npt.ArrayLike,
    contact_points: npt.ArrayLike,
    active: npt.ArrayLike | None = None,
    swing_tips: npt.ArrayLike | None = None,
    swing_active: npt.ArrayLike | None = None,
    v_tip_max: float | None = None,
    *,
    definition: Definition = "paper",
    direction: npt.ArrayLike | None = None,
    diagonal_pairs: npt.ArrayLike | None = None,
) -> np.ndarray:
    """S_H (...,) for a model in state (q, v), either definition (see `angular_momentum_stability`): COM,
    centroidal momentum and composite inertia come from the core (`center_of_mass`, `centroidal_momentum`,
    `subtree_mass_properties`). Gravity must point along -z."""
    gravity = np.asarray(model.gravity)
    if abs(gravity[0]) + abs(gravity[1]) > 0.0 or gravity[2] >= 0.0:
        raise ValueError(f"S_H assumes gravity along -z; the model has gravity {gravity}")
    momentum = np.asarray(lk.centroidal_momentum(model, q, v))
    _, coms, inertias = lk.subtree_mass_properties(model, q)
    return angular_momentum_stability(
        np.asarray(coms)[..., 0, :], momentum[..., :3], momentum[..., 3:], np.asarray(inertias)[..., 0, :, :],
        model.total_mass, contact_points, active, swing_tips, swing_active, v_tip_max, float(-gravity[2]),
        definition=definition, direction=direction, diagonal_pairs=diagonal_pairs,
    )


def worst_case(index: npt.ArrayLike, t: npt.ArrayLike) -> tuple[float, float]:
    """(minimum value, time of the minimum) of an index sampled at times t over a gait: its worst case."""
    values = float_array(index, "index", min_ndim=1)
    times = float_array(t, "t", min_ndim=1)
    if values.ndim != 1 or times.shape != values.shape:
        raise ValueError(f"index and t must be 1-D of equal length, got {values.shape} and {times.shape}")
    if values.size == 0:
        raise ValueError("index must hold at least one sample")
    worst = int(np.argmin(values))
    return float(values[worst]), float(times[worst])
