"""The second derivatives of the centre of mass (``lk.center_of_mass_hessian``: the q-Hessian of w . c) and of the
centroidal momentum (``lk.centroidal_momentum_hessian``: the (q, q) and (q, v) Hessians of w . h).

Against central differences of legkit's first-order kernels (``lk.center_of_mass_jacobian``,
``lk.centroidal_derivatives``, ``lk.centroidal_map``), q stepped by ``lk.integrate``, on random trees with every joint
kind; and in closed form on a pendulum.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given

import legkit as lk
from conftest import examples
from robots import Twin, rngs, twins
from test_derivatives import assert_hessian_of_slope, assert_slopes, tangent_differences
from test_dynamics_pinocchio import assert_close, note_case, state


@examples(40)
@given(tw=twins(max_bodies=40), rng=rngs())
def test_center_of_mass_hessian_is_the_slope_of_its_jacobian(tw: Twin, rng):
    q, _, _ = state(tw, rng)
    weights = rng.normal(size=3)
    note_case(tw, q=q)

    def slope(x: np.ndarray) -> np.ndarray:
        return weights @ np.asarray(lk.center_of_mass_jacobian(tw.model, x))

    assert_hessian_of_slope(tw.model, lk.center_of_mass_hessian(tw.model, q, weights), slope, q, "d2(w . c)/dq2")


@examples(40)
@given(tw=twins(max_bodies=40), rng=rngs())
def test_centroidal_momentum_hessian_is_the_slope_of_its_derivatives(tw: Twin, rng):
    assume(tw.nv > 0)  # the stacked differences below need a coordinate
    q, v, _ = state(tw, rng)
    weights = rng.normal(size=6)
    note_case(tw, q=q, v=v)

    def slopes(x: np.ndarray) -> np.ndarray:  # weights . (dh/dq, dh/dv = A_G)
        dh_dq = np.asarray(lk.centroidal_derivatives(tw.model, x, v, np.zeros(tw.nv))[0])
        return np.stack([weights @ dh_dq, weights @ np.asarray(lk.centroidal_map(tw.model, x))])

    qq, qv, gradient = lk.centroidal_momentum_hessian(tw.model, q, v, weights)
    assert_close(gradient, slopes(q)[0], "gradient")
    by_q = tangent_differences(tw.model, slopes, q)  # [which, e, d]
    assert_slopes(qq, by_q[0], "d2(w . h)/dq2")
    assert_slopes(qv, by_q[1].T, "d2(w . h)/dq dv")


def test_a_pendulum_bob_in_closed_form():
    """A bob of mass m at r below a revolute joint about y: c = r (-sin q, 0, -cos q), whose slopes are
    r (-cos q, 0, sin q) and r (sin q, 0, cos q); its momentum is m dc/dt (none about its own centre)."""
    m, r, q, w = 2.0, 0.7, 0.4, 1.3
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 1.0, 0.0], np.eye(4), lk.MassProperties.point(m, [0.0, 0.0, -r]), "bob")
    c, s = np.cos(q), np.sin(q)
    along, turned, bent = r * np.array([-c, 0.0, s]), r * np.array([s, 0.0, c]), r * np.array([c, 0.0, -s])
    weights = np.array([0.3, -0.2, 0.9, 0.5, -0.7, 0.1])
    hessian, gradient = lk.center_of_mass_hessian(model, [q], weights[:3])
    assert np.allclose(gradient, [weights[:3] @ along], rtol=0, atol=1e-15)
    assert np.allclose(hessian, [[weights[:3] @ turned]], rtol=0, atol=1e-15)
    qq, qv, gradient = lk.centroidal_momentum_hessian(model, [q], [w], weights)
    assert np.allclose(gradient, [m * w * weights[:3] @ turned], rtol=0, atol=1e-14)
    assert np.allclose(qq, [[m * w * weights[:3] @ bent]], rtol=0, atol=1e-14)
    assert np.allclose(qv, [[m * weights[:3] @ turned]], rtol=0, atol=1e-14)


def test_shapes_and_bad_arguments():
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1]))
    model.add_revolute(0, [1.0, 0.0, 0.0], np.eye(4), lk.MassProperties.point(1.0, [0.0, 0.0, -0.3]), "leg")
    q = np.tile(np.r_[np.zeros(6), 1.0, 0.0], (4, 1, 1))
    v = np.zeros((1, 3, model.nv))
    hessian, gradient = lk.center_of_mass_hessian(model, q, [0.0, 0.0, 1.0])
    assert hessian.shape == (4, 1, model.nv, model.nv) and gradient.shape == (4, 1, model.nv)
    qq, qv, gradient = lk.centroidal_momentum_hessian(model, q, v, np.ones(6))
    assert qq.shape == qv.shape == (4, 3, model.nv, model.nv) and gradient.shape == (4, 3, model.nv)
    with pytest.raises(ValueError, match="weights"):
        lk.center_of_mass_hessian(model, q, [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="weights"):
        lk.center_of_mass_hessian(model, q, [1.0, 0.0])
    with pytest.raises(ValueError, match="weights"):
        lk.centroidal_momentum_hessian(model, q, v, np.ones(3))
    with pytest.raises(ValueError, match="weights"):
        lk.centroidal_momentum_hessian(model, q, v, np.r_[np.ones(5), np.inf])
    with pytest.raises(ValueError, match=r"^v\b"):
        lk.centroidal_momentum_hessian(model, q, np.zeros(model.nv + 1), np.ones(6))
    with pytest.raises(ValueError, match=r"^q\b"):
        lk.center_of_mass_hessian(model, np.zeros(5), [1.0, 0.0, 0.0])
