"""The paper's Stability Performance 2: the angular-momentum stability index S_H.

For every edge of the support polygon the robot is treated as a rigid body that could tip about that edge.
Per edge (an edge point p, horizontal outward normal n, edge axis a = z x n, horizontal):

* H      = a . (k_G + (c - p) x P): the angular momentum about the edge [N m s]; k_G is the centroidal
           angular momentum, P the linear momentum. H > 0 tips the robot *outward* (over the edge).
* rho    = the COM offset from the edge axis, (c - p) minus its component along a; d = -n . rho is the
           horizontal COM distance inside the edge (d < 0: the COM is beyond it), h = rho_z, r = |rho|.
* I_e    = a^T I_G a + m r^2: the moment of inertia about the edge.
* H_ref  = sqrt(2 I_e m g (r - h)): the angular momentum whose kinetic energy H^2 / (2 I_e) just raises
           the COM from its height h to r, straight above the edge. A body rotating about the edge with
           |H| < H_ref turns back before the top, with |H| > H_ref it passes over it.
* H_max  = I_e v_tip_max / l: the largest tipping momentum a swing leg can still catch. Its tip, at
           distance l from the edge axis, moves at omega l while the body tips at omega = H / I_e; it can
           only come down in time if that is below the actuator-limited tip speed v_tip_max. l is the
           largest such distance among the swing tips beyond the edge (the most demanding one).

An edge side is *non-diagonal* when no swing-leg tip lies beyond it (nothing catches a fall that way);
this is every edge of a polygon with the other legs inside, and the outer side of a lateral leg pair.
It is *diagonal* when a swing tip lies beyond it: both sides of a diagonal leg pair in an amble or trot,
the inner side of a lateral pair. The index per edge side is:

    non-diagonal   d >= 0:  S = H_ref - H                         (the paper's case)
                   d <  0:  S = -H_ref - H                        (the COM is beyond: only a return with
                                                                   H <= -H_ref saves it)
    diagonal  (1)  d >= 0, H <= H_ref:   S = H_max + H_ref - H    (turns back before the edge)
              (2)  d >= 0, H >  H_ref:   S = H_max - sqrt(H^2 - H_ref^2)
                                                                  (passes the edge; the swing leg must
                                                                   absorb the residual momentum)
              (3)  d <  0, H >= -H_ref:  S = H_max - |H|          (leaning over the edge: falls, or turns
                                                                   and falls back through this pose with |H|)
              (4)  d <  0, H <  -H_ref:  S = H_max + sqrt(H^2 - H_ref^2)
                                                                  (swings back over the edge, away)

S_H(t) is the minimum over all edge sides; positive means stable. Quasi-statically (H = 0) a non-diagonal
edge gives S = sign(d) H_ref, so S_H changes sign exactly when the COM crosses a polygon edge. Cases (1)-(4)
agree where they meet except across the separatrix H = -H_ref of case (3)/(4), where the motion really does
bifurcate (fall back or swing over).

Reconstruction note: the diagonal-edge cases above are derived from the paper's definitions of H_ref (energy
to raise the COM over the edge) and H_max (swing-leg tip speed); the paper's own text for these four cases
was not available when this module was written, so check them against it before quoting numbers.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

import legkit as lk
from legkit._validation import float_array
from legkit.stability._validation import bool_mask, positive_scalar
from legkit.stability.support import _contacts, _hull


def angular_momentum_stability(
    com: npt.ArrayLike,
    linear_momentum: npt.ArrayLike,
    angular_momentum: npt.ArrayLike,
    inertia: npt.ArrayLike,
    mass: float,
    contact_points: npt.ArrayLike,
    active: npt.ArrayLike | None = None,
    swing_tips: npt.ArrayLike | None = None,
    swing_active: npt.ArrayLike | None = None,
    v_tip_max: float | None = None,
    gravity: float = 9.81,
) -> np.ndarray:
    """S_H (...,) [N m s]: minimum over the support edges of the angular-momentum index (module docstring).

    com: (..., 3) [m]; linear_momentum: (..., 3) [kg m/s]; angular_momentum: (..., 3) about the COM
    [N m s] (both as `lk.centroidal_momentum`); inertia: (..., 3, 3) about the COM, world frame [kg m^2];
    mass [kg]; contact_points: (..., k, 3) with optional active (..., k) bool (at least two distinct active
    contacts per sample, an edge to tip about: contacts closer than the support tolerance merge, see
    `legkit.stability.support` and `distinct_contact_count`); swing_tips: optional (..., s, 3) tips of legs in the air with
    optional swing_active (..., s) bool, which make the edges they lie beyond "diagonal"; v_tip_max [m/s]
    is required with swing_tips; gravity: magnitude [m/s^2] of a gravity pointing along -z.
    """
    per_edge = _edge_indices(
        com, linear_momentum, angular_momentum, inertia, mass, contact_points, active, swing_tips, swing_active,
        v_tip_max, gravity,
    )
    return np.min(per_edge, axis=-1)


def _edge_indices(
    com, linear_momentum, angular_momentum, inertia, mass, contact_points, active, swing_tips, swing_active,
    v_tip_max, gravity,
) -> np.ndarray:
    """(..., E) index per edge slot, +inf in slots that are not edges at that sample. Computed component by
    component in an (E, T) layout: the axis a = z x n is horizontal, so every product reduces to x/y terms."""
    c = float_array(com, "com", last=3)
    momentum = float_array(linear_momentum, "linear_momentum", last=3)
    k_g = float_array(angular_momentum, "angular_momentum", last=3)
    inertia_g = float_array(inertia, "inertia", min_ndim=2)
    if inertia_g.shape[-2:] != (3, 3):
        raise ValueError(f"inertia must have trailing shape (3, 3), got {inertia_g.shape}")
    m = positive_scalar(mass, "mass")
    g = positive_scalar(gravity, "gravity")
    points, mask = _contacts(contact_points, active)
    shape = np.broadcast_shapes(c.shape[:-1], momentum.shape[:-1], k_g.shape[:-1], inertia_g.shape[:-2], points.shape[:-2], mask.shape[:-1])
    if swing_tips is not None and v_tip_max is None:
        raise ValueError("v_tip_max is required when swing_tips is given")

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
    ii = flat(inertia_g, (3, 3))[:, :, sample]
    length = hull.length[edge, sample]
    nx, ny = hull.dy[edge, sample] / length, -hull.dx[edge, sample] / length  # outward (right of the CCW edge)
    ax, ay = -ny, nx  # a = z x n
    start = pts[hull.start_index[edge], :, sample].T  # (3, V): the 3-D start contact of every edge
    ox, oy, oz = cc[0] - start[0], cc[1] - start[1], cc[2] - start[2]
    d = -(nx * ox + ny * oy)  # rho = -d n + oz z: the offset perpendicular to the edge
    r = np.sqrt(d * d + oz * oz)
    # Rise of the COM to above the edge, r - oz, written as d^2 / (r + oz) when oz > 0 to avoid cancellation.
    rise = np.where(oz > 0.0, d * d / np.where(oz > 0.0, r + oz, 1.0), r - oz)
    inertia_edge = ii[0, 0] * ax * ax + 2.0 * ii[0, 1] * ax * ay + ii[1, 1] * ay * ay + m * r * r
    h_edge = ax * (kk[0] + oy * pp[2] - oz * pp[1]) + ay * (kk[1] + oz * pp[0] - ox * pp[2])
    h_ref = np.sqrt(2.0 * inertia_edge * m * g * rise)

    inside = d >= 0.0
    value = np.where(inside, h_ref - h_edge, -h_ref - h_edge)
    if swing_tips is not None:
        tips = float_array(swing_tips, "swing_tips", last=3, min_ndim=2)
        speed = positive_scalar(v_tip_max, "v_tip_max")
        tip_shape = np.broadcast_shapes(shape, tips.shape[:-2]) + tips.shape[-2:-1]
        tip_mask = flat(bool_mask(swing_active, "swing_active", tip_shape), tips.shape[-2:-1])[:, sample]
        tips = flat(tips, tips.shape[-2:])[:, :, sample]  # (s, 3, V)
        lever_sq = np.zeros_like(h_edge)
        for tip in range(tips.shape[0]):  # a few swing feet; vectorised over edges and samples
            rx, ry, rz = tips[tip, 0] - start[0], tips[tip, 1] - start[1], tips[tip, 2] - start[2]
            out = nx * rx + ny * ry  # beyond the edge if > 0; squared distance to the axis = out^2 + rz^2
            lever_sq = np.where((out > 0.0) & tip_mask[tip], np.maximum(lever_sq, out * out + rz * rz), lever_sq)
        lever = np.sqrt(lever_sq)
        diagonal = lever > 0.0
        h_max = inertia_edge * speed / np.where(diagonal, lever, 1.0)
        residual = np.sqrt(np.maximum(h_edge * h_edge - h_ref * h_ref, 0.0))
        caught = h_max + np.where(
            inside,
            np.where(h_edge <= h_ref, h_ref - h_edge, -residual),  # cases (1), (2)
            np.where(h_edge >= -h_ref, -np.abs(h_edge), residual),  # cases (3), (4)
        )
        value = np.where(diagonal, caught, value)
    index = np.full(hull.valid.shape, np.inf)  # (E, T); slots that are not edges stay +inf
    index[edge, sample] = value
    return np.moveaxis(index, -1, 0).reshape(shape + (index.shape[0],))


def angular_momentum_stability_of_model(
    model: lk.Model,
    q: npt.ArrayLike,
    v: npt.ArrayLike,
    contact_points: npt.ArrayLike,
    active: npt.ArrayLike | None = None,
    swing_tips: npt.ArrayLike | None = None,
    swing_active: npt.ArrayLike | None = None,
    v_tip_max: float | None = None,
) -> np.ndarray:
    """S_H (...,) for a model in state (q, v): COM, centroidal momentum and composite inertia come from the
    core (`center_of_mass`, `centroidal_momentum`, `subtree_mass_properties`). Gravity must point along -z."""
    gravity = np.asarray(model.gravity)
    if abs(gravity[0]) + abs(gravity[1]) > 0.0 or gravity[2] >= 0.0:
        raise ValueError(f"S_H assumes gravity along -z; the model has gravity {gravity}")
    momentum = np.asarray(lk.centroidal_momentum(model, q, v))
    _, coms, inertias = lk.subtree_mass_properties(model, q)
    return angular_momentum_stability(
        np.asarray(coms)[..., 0, :], momentum[..., :3], momentum[..., 3:], np.asarray(inertias)[..., 0, :, :],
        model.total_mass, contact_points, active, swing_tips, swing_active, v_tip_max, float(-gravity[2]),
    )


def worst_case(index: npt.ArrayLike, t: npt.ArrayLike) -> tuple[float, float]:
    """(minimum value, time of the minimum) of an index sampled at times t over a gait: its worst case."""
    values = float_array(index, "index", min_ndim=1)
    times = float_array(t, "t", min_ndim=1)
    if values.ndim != 1 or times.shape != values.shape:
        raise ValueError(f"index and t must be 1-D of equal length, got {values.shape} and {times.shape}")
    worst = int(np.argmin(values))
    return float(values[worst]), float(times[worst])
