"""The second derivatives of inverse dynamics (``lk.rnea_second_order_derivatives``) against central differences of
Pinocchio's first derivatives (``computeRNEADerivatives`` and ``crba``: an independent implementation; Pinocchio's
Python bindings do not expose its second-order algorithm) on random trees of every joint kind (tests/robots.py), q
stepped on its tangent space; and their use as a Lagrangian's Hessian."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from hypothesis import given

import legkit as lk
from conftest import examples
from robots import Twin, rngs, twins
from test_derivatives import assert_slopes, coordinate_differences, pinocchio, tangent_differences
from test_dynamics_pinocchio import note_case, pin_sym, state


def pinocchio_first(tw: Twin, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pinocchio's dtau/dq, dtau/dv and M at legkit's (q, v, a), in legkit's coordinates."""
    dq, dv, _ = pinocchio(pin.computeRNEADerivatives, tw, tw.q_pin(q), tw.v_pin(v), tw.v_pin(a))
    mass = pin_sym(pin.crba(tw.pin_model, tw.data(), tw.q_pin(q)).copy())
    return tw.m_lk(dq), tw.m_lk(dv), tw.m_lk(mass)


@examples(25)
@given(tw=twins(max_bodies=12), rng=rngs())
def test_second_derivatives_are_the_slopes_of_pinocchios_first(tw: Twin, rng):
    q, v, a = state(tw, rng)
    note_case(tw, q=q, v=v, a=a)
    dqdq, dvdv, dqdv, dadq = lk.rnea_second_order_derivatives(tw.model, q, v, a)
    assert dqdq.shape == (tw.nv,) * 3
    assert_slopes(dqdq, tangent_differences(tw.model, lambda x: pinocchio_first(tw, x, v, a)[0], q), "d2tau/dqdq")
    assert_slopes(dadq, tangent_differences(tw.model, lambda x: pinocchio_first(tw, x, v, a)[2], q), "d2tau/dadq")
    assert_slopes(dvdv, coordinate_differences(lambda x: pinocchio_first(tw, q, x, a)[1], v), "d2tau/dvdv")
    assert_slopes(dqdv, coordinate_differences(lambda x: pinocchio_first(tw, q, x, a)[0], v), "d2tau/dqdv")


@examples(10)
@given(tw=twins(max_bodies=8), rng=rngs())
def test_batches_and_the_multipliers_hessian(tw: Twin, rng):
    """A batch gives each state's tensors; lam^T tau's Hessian by einsum is the slope of lam^T dtau/dq."""
    (q0, v0, a0), (q1, v1, a1) = state(tw, rng), state(tw, rng)
    batch = lk.rnea_second_order_derivatives(tw.model, np.stack([q0, q1]), np.stack([v0, v1]), np.stack([a0, a1]))
    for k, (q, v, a) in enumerate([(q0, v0, a0), (q1, v1, a1)]):
        for got, want in zip(batch, lk.rnea_second_order_derivatives(tw.model, q, v, a)):
            assert np.array_equal(got[k], want)
    lam = rng.standard_normal(tw.nv)
    hessian = np.einsum("i,ijk->jk", lam, batch[0][0])
    want = tangent_differences(tw.model, lambda x: lam @ lk.rnea_derivatives(tw.model, x, v0, a0)[0], q0)
    assert_slopes(hessian, want, "lam^T d2tau/dqdq")
