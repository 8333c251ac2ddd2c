"""The analytic derivatives of the centroidal momentum (``lk.centroidal_derivatives``) and of the centre of mass
(``lk.center_of_mass_jacobian``).

Differential tests against Pinocchio's ``computeCentroidalDynamicsDerivatives`` and ``jacobianCenterOfMass`` on random
trees (tests/robots.py: every joint kind, fixed and free-flyer bases), at 1e-9 relative as the other dynamics, on twins
whose bodies welded to a fixed base are massless (Pinocchio never counts them; see tests/test_dynamics_pinocchio.py);
and, without Pinocchio, against five-point central differences of legkit's own ``centroidal_momentum``,
``centroidal_momentum_rate`` and ``center_of_mass``, q stepped on its tangent space by ``lk.integrate``, at 1e-6
relative. The rate hdot is the one ``centroidal_momentum_rate`` returns, without gravity, as Pinocchio's (checked
below); with gravity it would differ by the constant weight in its linear part, and the derivatives not at all.
Batches against per-row calls and bad input are in tests/test_dynamics_pinocchio.py (BATCHED, BAD_CALLS), the robots
of example-robot-data in tests/test_urdf_robots.py.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from hypothesis import assume, given

import legkit as lk
from conftest import examples
from robots import Twin, rngs
from test_derivatives import assert_slopes, coordinate_differences, tangent_differences
from test_dynamics_pinocchio import assert_close, com_twins, note_case, state, total_mass

NAMES = ("dh/dq", "dhdot/dq", "dhdot/dv", "dhdot/da")


def pin_columns(tw: Twin, matrix, rows: int) -> np.ndarray:
    """A Pinocchio (rows, nv) matrix, copied (it may be a view of a Data), its columns in legkit's order."""
    return tw.cols_lk(np.array(matrix, dtype=np.float64).reshape(rows, tw.nv))


@examples(60)
@given(tw=com_twins(), rng=rngs())
def test_centroidal_derivatives_match_pinocchio(tw: Twin, rng):
    assume(total_mass(tw) > 0)
    q, v, a = state(tw, rng)
    note_case(tw, q=q, v=v, a=a)
    data = tw.data()
    want = [pin_columns(tw, x, 6) for x in pin.computeCentroidalDynamicsDerivatives(tw.pin_model, data, tw.q_pin(q), tw.v_pin(v), tw.v_pin(a))]
    for got, expected, what in zip(lk.centroidal_derivatives(tw.model, q, v, a), want, NAMES):
        assert_close(got, expected, what)
    # What Pinocchio differentiates is legkit's momentum and rate: both leave gravity out of the rate.
    assert_close(lk.centroidal_momentum(tw.model, q, v), np.r_[data.hg.linear, data.hg.angular], "h")
    assert_close(lk.centroidal_momentum_rate(tw.model, q, v, a), np.r_[data.dhg.linear, data.dhg.angular], "hdot")


@examples(60)
@given(tw=com_twins(), rng=rngs())
def test_center_of_mass_jacobian_matches_pinocchio(tw: Twin, rng):
    assume(total_mass(tw) > 0)
    q = tw.random_q(rng)
    note_case(tw, q=q)
    want = pin_columns(tw, pin.jacobianCenterOfMass(tw.pin_model, tw.data(), tw.q_pin(q)), 3)
    assert_close(lk.center_of_mass_jacobian(tw.model, q), want, "dc/dq")


@examples(40)
@given(tw=com_twins(max_bodies=30), rng=rngs())
def test_centroidal_derivatives_are_the_slopes_of_the_momentum_and_its_rate(tw: Twin, rng):
    q, v, a = state(tw, rng)
    note_case(tw, q=q, v=v, a=a)
    m = tw.model
    dh_dq, dhdot_dq, dhdot_dv, dhdot_da = lk.centroidal_derivatives(m, q, v, a)
    assert_slopes(dh_dq, tangent_differences(m, lambda x: lk.centroidal_momentum(m, x, v), q), "dh/dq")
    assert_slopes(dhdot_da, coordinate_differences(lambda x: lk.centroidal_momentum(m, q, x), v), "dh/dv")
    assert_slopes(dhdot_dq, tangent_differences(m, lambda x: lk.centroidal_momentum_rate(m, x, v, a), q), "dhdot/dq")
    assert_slopes(dhdot_dv, coordinate_differences(lambda x: lk.centroidal_momentum_rate(m, q, x, a), v), "dhdot/dv")
    assert_slopes(dhdot_da, coordinate_differences(lambda x: lk.centroidal_momentum_rate(m, q, v, x), a), "dhdot/da")
    assert_close(dhdot_da, lk.centroidal_map(m, q), "A_G")
    assert_slopes(lk.center_of_mass_jacobian(m, q), tangent_differences(m, lambda x: lk.center_of_mass(m, x), q), "dc/dq")


def test_pendulum_in_closed_form():
    """A point mass m on a massless rod of length r turning about y: its COM is c = r (-sin q, 0, -cos q), the momentum
    h = [m c' v; 0] (a point has no angular momentum about itself), and its rate [m (c'' v^2 + c' a); 0]."""
    m, r = 2.0, 0.7
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 1.0, 0.0], np.eye(4), lk.MassProperties.point(m, [0.0, 0.0, -r]), "bob")
    q, v, a = 0.4, 1.3, -0.6
    s, c = np.sin(q), np.cos(q)
    dc, ddc, dddc = r * np.array([-c, 0.0, s]), r * np.array([s, 0.0, c]), r * np.array([c, 0.0, -s])
    dh_dq, dhdot_dq, dhdot_dv, dhdot_da = lk.centroidal_derivatives(model, [q], [v], [a])
    zero = np.zeros(3)
    np.testing.assert_allclose(lk.center_of_mass_jacobian(model, [q])[:, 0], dc, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dh_dq[:, 0], np.r_[m * ddc * v, zero], rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dhdot_dq[:, 0], np.r_[m * (dddc * v * v + ddc * a), zero], rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dhdot_dv[:, 0], np.r_[2.0 * m * ddc * v, zero], rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(dhdot_da[:, 0], np.r_[m * dc, zero], rtol=1e-14, atol=1e-15)


def test_outputs_are_fresh_arrays_with_batch_shapes():
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1]))
    model.add_revolute(0, [1.0, 0.0, 0.0], np.eye(4), lk.MassProperties.point(1.0, [0.0, 0.0, -0.3]), "leg")
    q = np.tile(np.r_[np.zeros(6), 1.0, 0.0], (4, 1, 1))
    v, a = np.ones((1, 3, model.nv)), np.ones(model.nv)
    outputs = lk.centroidal_derivatives(model, q, v, a)
    assert [x.shape for x in outputs] == [(4, 3, 6, model.nv)] * 4
    for k, x in enumerate(outputs):
        x[...] = np.nan  # the outputs do not overlap
        assert not any(np.isnan(y).any() for y in outputs[k + 1:])
    assert lk.center_of_mass_jacobian(model, q).shape == (4, 1, 3, model.nv)


def test_a_massless_model_has_zero_derivatives():
    """Its COM is the origin by convention (``center_of_mass``), and so does not move."""
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 0.0, 1.0], np.eye(4), lk.MassProperties.zero(), "massless")
    assert all(np.array_equal(x, np.zeros((6, 1))) for x in lk.centroidal_derivatives(model, [0.1], [0.2], [0.3]))
    assert np.array_equal(lk.center_of_mass_jacobian(model, [0.1]), np.zeros((3, 1)))
