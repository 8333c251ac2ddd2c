"""The analytic derivatives of the dynamics (``lk.rnea_derivatives``, ``lk.aba_derivatives``).

Differential tests against Pinocchio's ``computeRNEADerivatives`` and ``computeABADerivatives`` on random trees
(tests/robots.py: every joint kind, helical included, fixed and free-flyer bases, armature on half of them, external
forces), at 1e-9 relative as the other dynamics; and, without Pinocchio, against central differences of legkit's own
``rnea`` and ``aba`` (the five-point stencil, h = 1e-4, so that the rounding of large accelerations stays below the
tolerance), with q stepped on its tangent space by ``lk.integrate`` (q (+) h e_j), at 1e-6 relative.
The robots of example-robot-data are compared in tests/test_urdf_robots.py.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given

import legkit as lk
from conftest import examples
from robots import Twin, rngs, twins
from test_dynamics_pinocchio import assert_close, dynamics_case, note_case, pin_f_ext, pin_sym, state

STEP = 1e-4
FD_RTOL = 1e-6


def pinocchio(function, tw: Twin, *args) -> tuple[np.ndarray, ...]:
    """Pinocchio's derivatives, copied while their Data lives: the arrays Pinocchio's Python bindings return are views
    of the Data's own matrices, which a temporary Data frees as soon as the call returns."""
    data = tw.data()
    return tuple(np.array(x) for x in function(tw.pin_model, data, *args))


def differences(f, x: np.ndarray, step, count: int, h: float = STEP) -> np.ndarray:
    """f's slopes along step(x, j, h) for j < count, by the five-point stencil (error O(h^4)): shaped f's output then
    count."""

    def slope(j: int) -> np.ndarray:
        at = [f(step(x, j, k * h)) for k in (-2, -1, 1, 2)]
        return (at[0] - 8 * at[1] + 8 * at[2] - at[3]) / (12 * h)

    return np.moveaxis(np.array([slope(j) for j in range(count)]), 0, -1)


def tangent_differences(model: lk.Model, f, q: np.ndarray, h: float = STEP) -> np.ndarray:
    """Central differences of f along q (+) h e_j for each velocity coordinate j."""
    return differences(f, q, lambda x, j, h: lk.integrate(model, x, np.eye(model.nv)[j], h), model.nv, h)


def coordinate_differences(f, x: np.ndarray, h: float = STEP) -> np.ndarray:
    """Central differences of f along each coordinate of x."""
    return differences(f, x, lambda x, j, h: x + h * np.eye(len(x))[j], len(x), h)


#: The steps `settled` tries, largest first.
SETTLING_STEPS = (1e-3, 3e-4, 1e-4, 3e-5)


def settled(slopes_at) -> np.ndarray:
    """slopes_at(h), central differences (..., count) at step h, at the step of `SETTLING_STEPS` whose estimate changes
    least to the next smaller step, chosen per column. Rounding grows as h shrinks and truncation as it grows, and
    which dominates depends on the function: a contact solve of condition 3e3 lost 1e-5 to rounding at h = 1e-4, a
    19-body chain 6e-3 to truncation at 1e-3."""
    estimates = np.array([slopes_at(h) for h in SETTLING_STEPS])
    change = np.abs(np.diff(estimates, axis=0)).reshape(len(SETTLING_STEPS) - 1, -1, estimates.shape[-1]).max(axis=1)
    best = np.argmin(change, axis=0)
    return np.stack([estimates[best[j], ..., j] for j in range(estimates.shape[-1])], axis=-1)


def assert_slopes(got, want, what: str) -> None:
    scale = max(1.0, float(np.abs(want).max(initial=0.0)))
    error = float(np.abs(np.asarray(got) - want).max(initial=0.0))
    assert error <= FD_RTOL * scale, f"{what}: max error {error:.3e} > {FD_RTOL:g} * {scale:.3e}"


def assert_hessian_of_slope(model: lk.Model, hessian_and_gradient, slope, q: np.ndarray, what: str) -> None:
    """A scalar's (Hessian, gradient) in q, as the Hessian kernels return them: the gradient is `slope` at q and the
    Hessian the tangent differences of `slope`."""
    hessian, gradient = hessian_and_gradient
    assert_close(gradient, slope(q), "gradient")
    assert_slopes(hessian, tangent_differences(model, slope, q), what)


#: legkit's derivatives, Pinocchio's, the input given besides q and v, and the names of legkit's outputs, compared with
#: Pinocchio's first ones in order (RNEA's third, the mass matrix, is not).
DYNAMICS_DERIVATIVES = {
    "rnea": (lk.rnea_derivatives, pin.computeRNEADerivatives, "a", ("dtau/dq", "dtau/dv")),
    "aba": (lk.aba_derivatives, pin.computeABADerivatives, "tau", ("dddq/dq", "dddq/dv", "dddq/dtau")),
}


@pytest.mark.parametrize("with_f_ext", [False, True], ids=["no_f_ext", "f_ext"])
@pytest.mark.parametrize("algorithm", DYNAMICS_DERIVATIVES)
@examples(60)
@given(tw=twins(), rng=rngs())
def test_dynamics_derivatives_match_pinocchio(algorithm, with_f_ext, tw: Twin, rng):
    ours, theirs, given_input, names = DYNAMICS_DERIVATIVES[algorithm]
    q, v, x, f = dynamics_case(tw, rng, with_f_ext, given=given_input)
    want = pinocchio(theirs, tw, tw.q_pin(q), tw.v_pin(v), tw.v_pin(x), *pin_f_ext(tw, f))
    got = ours(tw.model, q, v, x, f)
    assert len(got) == len(names)
    for got_k, want_k, name in zip(got, want, names):
        # dddq/dtau is the inverse mass matrix, of which Pinocchio fills the upper triangle.
        assert_close(got_k, tw.m_lk(pin_sym(want_k) if name == "dddq/dtau" else want_k), name)


@examples(40)
@given(tw=twins(max_bodies=30), rng=rngs())
def test_rnea_derivatives_are_the_slopes_of_rnea(tw: Twin, rng):
    q, v, a = state(tw, rng)
    f = tw.random_f_ext(rng)
    note_case(tw, q=q, v=v, a=a, f_ext=f)
    dq, dv = lk.rnea_derivatives(tw.model, q, v, a, f)
    assert_slopes(dq, tangent_differences(tw.model, lambda x: lk.rnea(tw.model, x, v, a, f), q), "dtau/dq")
    assert_slopes(dv, coordinate_differences(lambda x: lk.rnea(tw.model, q, x, a, f), v), "dtau/dv")
    # dtau/da is the mass matrix.
    assert_slopes(lk.crba(tw.model, q), coordinate_differences(lambda x: lk.rnea(tw.model, q, v, x, f), a), "dtau/da")


@examples(40)
@given(tw=twins(max_bodies=30), rng=rngs())
def test_aba_derivatives_are_the_slopes_of_aba(tw: Twin, rng):
    q, v, tau, f = dynamics_case(tw, rng, with_f_ext=True, given="tau")
    dq, dv, dtau = lk.aba_derivatives(tw.model, q, v, tau, f)
    assert_slopes(dq, tangent_differences(tw.model, lambda x: lk.aba(tw.model, x, v, tau, f), q), "dddq/dq")
    assert_slopes(dv, coordinate_differences(lambda x: lk.aba(tw.model, q, x, tau, f), v), "dddq/dv")
    assert_slopes(dtau, coordinate_differences(lambda x: lk.aba(tw.model, q, v, x, f), tau), "dddq/dtau")


def test_pendulum_derivatives_in_closed_form():
    """A point mass m on a massless rod of length r about y: tau = m r^2 a + m g r sin(q), so dtau/dq = m g r cos(q),
    dtau/dv = 0, and da/dq = -g cos(q) / r, da/dtau = 1 / (m r^2)."""
    m, r, g = 2.0, 0.7, lk.STANDARD_GRAVITY
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 1.0, 0.0], np.eye(4), lk.MassProperties.point(m, [0.0, 0.0, -r]), "bob")
    q, v = np.array([0.4]), np.array([1.3])
    dq, dv = lk.rnea_derivatives(model, q, v, [0.5])
    # Turning about +y by q moves the bob to (-l sin q, 0, -l cos q): gravity's torque about +y is -m g l sin q.
    assert np.allclose(dq, [[m * g * r * np.cos(q[0])]], rtol=1e-14)
    assert np.allclose(dv, [[0.0]], atol=1e-15)
    add, adv, adtau = lk.aba_derivatives(model, q, v, [0.0])
    assert np.allclose(add, [[-g * np.cos(q[0]) / r]], rtol=1e-14)
    assert np.allclose(adv, [[0.0]], atol=1e-15)
    assert np.allclose(adtau, [[1.0 / (m * r * r)]], rtol=1e-14)


def test_outputs_are_fresh_arrays_with_batch_shapes():
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1]))
    model.add_revolute(0, [1.0, 0.0, 0.0], np.eye(4), lk.MassProperties.point(1.0, [0.0, 0.0, -0.3]), "leg")
    q = np.tile(np.r_[np.zeros(6), 1.0, 0.0], (4, 1, 1))
    v, a = np.zeros((1, 3, model.nv)), np.zeros(model.nv)
    dq, dv = lk.rnea_derivatives(model, q, v, a)
    assert dq.shape == dv.shape == (4, 3, model.nv, model.nv)
    dq[...] = 1.0  # the outputs do not overlap
    assert not np.any(dv == 1.0)
    outputs = lk.aba_derivatives(model, q, v, a)
    assert [x.shape for x in outputs] == [(4, 3, model.nv, model.nv)] * 3


def test_a_singular_mass_matrix_is_refused():
    """A massless chain has a singular mass matrix: aba_derivatives raises as aba does (RuntimeError, a numerical
    failure), rnea_derivatives does not need M."""
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0.0, 0.0, 1.0], np.eye(4), lk.MassProperties.zero(), "massless")
    with pytest.raises(RuntimeError, match="singular"):
        lk.aba(model, [0.1], [0.0], [0.0])
    with pytest.raises(RuntimeError, match="singular"):
        lk.aba_derivatives(model, [0.1], [0.0], [0.0])
    dq, dv = lk.rnea_derivatives(model, [0.1], [0.0], [0.0])
    assert np.array_equal(dq, [[0.0]]) and np.array_equal(dv, [[0.0]])
