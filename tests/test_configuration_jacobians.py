"""The configuration space: ``lk.difference`` and the Jacobians of ``lk.integrate`` and ``lk.difference``.

Differential tests against Pinocchio's ``difference``, ``dIntegrate`` and ``dDifference`` on random trees
(tests/robots.py: every joint kind, helical included, fixed and free-flyer bases) at 1e-9 relative, as the other
dynamics; then, without Pinocchio, the properties that define them: q0 (+) (q1 (-) q0) = q1 and (q0 (+) v) (-) q0 = v,
the chain rules d(-)/dq1 d(+)/dv = dt and d(-)/dq0 = -d(-)/dq1 d(+)/dq, and the Jacobians against five-point
central differences (inputs stepped on their tangent spaces with ``lk.integrate``, configurations measured with
``lk.difference``); the free flyer's Jacobians near zero angle and near pi; batch shapes; bad input.
The Rust suite (crates/dynamics/tests/configuration.rs) checks the same slopes at more angles.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from robots import Twin, build_twin, rngs, twins
from test_derivatives import assert_slopes, coordinate_differences, tangent_differences
from test_dynamics_pinocchio import _bad_q, _mentions, _with_nan, assert_close, note_case

ARG0, ARG1 = pin.ArgumentPosition.ARG0, pin.ArgumentPosition.ARG1


def pinocchio(function, tw: Twin, *args) -> np.ndarray:
    """Pinocchio's Jacobian in legkit's order, copied (Pinocchio's Python functions may hand back views)."""
    return tw.m_lk(np.array(function(tw.pin_model, *args)))


def below_pi(tw: Twin, v: np.ndarray) -> np.ndarray:
    """v with the base's and the ball joints' rotations halved: random_v's angles reach 3 sqrt(3) > pi, halved they
    stay below, where (-) inverts (+)."""
    v = v.copy()
    for k in tw.rotations:
        v[k : k + 3] *= 0.5
    return v


def same_configuration(tw: Twin, got: np.ndarray, want: np.ndarray) -> None:
    """Equal coordinates, quaternions up to their sign (q and -q are one rotation)."""
    got = np.array(got)
    for k in ([3] if tw.floating else []) + tw.quaternions:
        if np.dot(got[k : k + 4], want[k : k + 4]) < 0.0:
            got[k : k + 4] *= -1.0
    assert_close(got, want, "configuration")


# --------------------------------------------------------------------------------------------------
# Against Pinocchio
# --------------------------------------------------------------------------------------------------


@examples(60)
@given(tw=twins(), rng=rngs())
def test_difference_matches_pinocchio(tw: Twin, rng):
    q0, q1 = tw.random_q(rng), tw.random_q(rng)
    note_case(tw, q0=q0, q1=q1)
    want = pin.difference(tw.pin_model, tw.q_pin(q0), tw.q_pin(q1))
    assert_close(lk.difference(tw.model, q0, q1), tw.v_lk(want), "difference")


@examples(30)
@given(tw=twins(), rng=rngs())
def test_integrate_without_dt_is_pinocchios_integrate(tw: Twin, rng):
    """``lk.integrate(model, q, v)`` as ``pin.integrate(model, q, v)``: dt defaults to 1."""
    q, v = tw.random_q(rng), below_pi(tw, tw.random_v(rng))
    note_case(tw, q=q, v=v)
    got = lk.integrate(tw.model, q, v)
    np.testing.assert_array_equal(got, lk.integrate(tw.model, q, v, 1.0))
    want = pin.integrate(tw.pin_model, tw.q_pin(q), tw.v_pin(v))
    assert_close(lk.difference(tw.model, q, got), tw.v_lk(pin.difference(tw.pin_model, tw.q_pin(q), want)), "integrate")


@examples(60)
@given(tw=twins(), rng=rngs(), dt=st.sampled_from([1.0, 1e-3, 0.37, -0.8]))
def test_integrate_jacobians_match_pinocchio(tw: Twin, rng, dt):
    q, v = tw.random_q(rng), tw.random_v(rng)
    note_case(tw, q=q, v=v)
    dq, dv = lk.integrate_jacobians(tw.model, q, v, dt)
    step = tw.v_pin(v * dt)
    assert_close(dq, pinocchio(pin.dIntegrate, tw, tw.q_pin(q), step, ARG0), "d(q + v dt)/dq")
    assert_close(dv, dt * pinocchio(pin.dIntegrate, tw, tw.q_pin(q), step, ARG1), "d(q + v dt)/dv")


@examples(60)
@given(tw=twins(), rng=rngs())
def test_difference_jacobians_match_pinocchio(tw: Twin, rng):
    q0, q1 = tw.random_q(rng), tw.random_q(rng)
    note_case(tw, q0=q0, q1=q1)
    d0, d1 = lk.difference_jacobians(tw.model, q0, q1)
    assert_close(d0, pinocchio(pin.dDifference, tw, tw.q_pin(q0), tw.q_pin(q1), ARG0), "d(q1 - q0)/dq0")
    assert_close(d1, pinocchio(pin.dDifference, tw, tw.q_pin(q0), tw.q_pin(q1), ARG1), "d(q1 - q0)/dq1")


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 1e-3, 1e-2, 0.1, 1.0, 3.0, np.pi - 1e-6])
def test_free_flyer_matches_pinocchio_from_zero_angle_to_pi(angle):
    """A base turned by `angle` about a random axis (legkit's series below 0.1 rad, its closed forms above) agrees
    with Pinocchio at 1e-9, except near 1e-3 rad, where Pinocchio's Jexp6 and Jlog6 lose up to 6e-8 to cancellation
    (in their beta'/theta; legkit's agree with central differences to 2e-12 there): 1e-7 there. And d1 dv = I."""
    rng = np.random.default_rng(3)
    tw = build_twin(rng, 1, True)
    axis = rng.normal(size=3)
    v = np.r_[rng.uniform(-1.0, 1.0, 3), angle * axis / np.linalg.norm(axis)]
    q0 = tw.random_q(rng)
    q1 = lk.integrate(tw.model, q0, v, 1.0)
    tolerance = 1e-7 if 1e-4 < angle < 1e-2 else 1e-9
    got = [*lk.integrate_jacobians(tw.model, q0, v), *lk.difference_jacobians(tw.model, q0, q1)]
    want = [
        pinocchio(pin.dIntegrate, tw, q0, v, ARG0),
        pinocchio(pin.dIntegrate, tw, q0, v, ARG1),
        pinocchio(pin.dDifference, tw, q0, q1, ARG0),
        pinocchio(pin.dDifference, tw, q0, q1, ARG1),
    ]
    for name, ours, theirs in zip(["dq", "dv", "d0", "d1"], got, want):
        error = float(np.abs(ours - theirs).max())
        assert np.all(np.isfinite(ours)) and error <= tolerance, f"angle {angle}: {name} error {error:.3e}"
    assert np.abs(got[3] @ got[1] - np.eye(6)).max() < 1e-12
    assert np.abs(lk.difference(tw.model, q0, q1) - v).max() < 1e-9


# --------------------------------------------------------------------------------------------------
# Properties, without Pinocchio
# --------------------------------------------------------------------------------------------------


@examples(60)
@given(tw=twins(), rng=rngs())
def test_integrate_and_difference_invert_each_other(tw: Twin, rng):
    q0, q1, v = tw.random_q(rng), tw.random_q(rng), below_pi(tw, tw.random_v(rng))
    note_case(tw, q0=q0, q1=q1, v=v)
    same_configuration(tw, lk.integrate(tw.model, q0, lk.difference(tw.model, q0, q1), 1.0), q1)
    assert_close(lk.difference(tw.model, q0, lk.integrate(tw.model, q0, v, 1.0)), v, "(q0 + v) - q0")
    assert_close(lk.difference(tw.model, q0, q0), np.zeros(tw.nv), "q0 - q0")


@examples(60)
@given(tw=twins(), rng=rngs(), dt=st.floats(-1.0, 1.0).filter(lambda x: abs(x) > 1e-3))
def test_chain_rules(tw: Twin, rng, dt):
    """With q1 = q0 (+) v dt: (q0 (+) x dt) (-) q0 = x dt near x = v gives d1 dv = dt I; q1 (-) (q0 (+) e) = (q0 (+) v dt)
    (-) (q0 (+) e) gives d0 = -d1 dq."""
    q0, v = tw.random_q(rng), below_pi(tw, tw.random_v(rng))
    note_case(tw, q0=q0, v=v)
    q1 = lk.integrate(tw.model, q0, v, dt)
    dq, dv = lk.integrate_jacobians(tw.model, q0, v, dt)
    d0, d1 = lk.difference_jacobians(tw.model, q0, q1)
    assert_close(d1 @ dv, dt * np.eye(tw.nv), "d1 dv")
    assert_close(d0, -d1 @ dq, "d0 = -d1 dq")


@examples(40)
@given(tw=twins(max_bodies=30), rng=rngs(), dt=st.sampled_from([1.0, 0.25, -0.6]))
def test_jacobians_are_the_slopes(tw: Twin, rng, dt):
    q0, v = tw.random_q(rng), below_pi(tw, tw.random_v(rng))
    note_case(tw, q0=q0, v=v)
    model, q1 = tw.model, lk.integrate(tw.model, q0, v, dt)
    dq, dv = lk.integrate_jacobians(model, q0, v, dt)
    assert_slopes(dq, tangent_differences(model, lambda x: lk.difference(model, q1, lk.integrate(model, x, v, dt)), q0), "d(+)/dq")
    assert_slopes(dv, coordinate_differences(lambda x: lk.difference(model, q1, lk.integrate(model, q0, x, dt)), v), "d(+)/dv")
    d0, d1 = lk.difference_jacobians(model, q0, q1)
    assert_slopes(d0, tangent_differences(model, lambda x: lk.difference(model, x, q1), q0), "d(-)/dq0")
    assert_slopes(d1, tangent_differences(model, lambda x: lk.difference(model, q0, x), q1), "d(-)/dq1")


def test_one_coordinate_joints_in_closed_form():
    """Revolute, prismatic and helical coordinates add: the Jacobians are 1, dt, -1 and 1."""
    model = lk.Model(floating_base=False)
    body = lk.MassProperties.point(1.0, [0.0, 0.0, -0.2])
    model.add_revolute(0, [0.0, 1.0, 0.0], np.eye(4), body, "r")
    model.add_prismatic(1, [1.0, 0.0, 0.0], np.eye(4), body, "p")
    model.add_helical(2, [0.0, 0.0, 1.0], 0.05, np.eye(4), body, "h")
    q0, q1 = np.array([0.3, -0.2, 7.0]), np.array([-3.0, 0.4, -5.0])
    assert np.array_equal(lk.difference(model, q0, q1), q1 - q0)
    dq, dv = lk.integrate_jacobians(model, q0, [1.0, 2.0, 3.0], 0.1)
    assert np.array_equal(dq, np.eye(3)) and np.array_equal(dv, 0.1 * np.eye(3))
    d0, d1 = lk.difference_jacobians(model, q0, q1)
    assert np.array_equal(d0, -np.eye(3)) and np.array_equal(d1, np.eye(3))


# --------------------------------------------------------------------------------------------------
# Batches and bad input
# --------------------------------------------------------------------------------------------------


def _floating_twin() -> Twin:
    return build_twin(np.random.default_rng(5), 6, True)


@pytest.mark.parametrize("batch", [5, 300])
def test_batches_equal_rows_and_broadcast(batch):
    tw, rng = _floating_twin(), np.random.default_rng(6)
    q0 = np.stack([tw.random_q(rng) for _ in range(batch)])
    q1 = np.stack([tw.random_q(rng) for _ in range(batch)])
    v = np.stack([tw.random_v(rng) for _ in range(batch)])
    calls = {
        "difference": (lambda *a: (lk.difference(tw.model, *a),), (q0, q1)),
        "integrate_jacobians": (lambda *a: lk.integrate_jacobians(tw.model, *a, 0.3), (q0, v)),
        "difference_jacobians": (lambda *a: lk.difference_jacobians(tw.model, *a), (q0, q1)),
    }
    for name, (call, args) in calls.items():
        got = call(*args)
        for b in range(batch):
            for out, row in zip(got, call(*(x[b] for x in args))):
                assert np.array_equal(out[b], row), f"{name}: row {b} differs from its own call"
        # (batch, 1) against (3,): (batch, 3), each pair.
        broadcast = call(args[0][:, None, :], args[1][:3])
        assert all(out.shape[:2] == (batch, 3) for out in broadcast), name
        assert all(np.array_equal(out[batch - 1, 2], row) for out, row in zip(broadcast, call(args[0][-1], args[1][2]))), name


def test_output_shapes_and_independence():
    tw, rng = _floating_twin(), np.random.default_rng(8)
    q = np.tile(tw.random_q(rng), (4, 1, 1))
    v = np.tile(tw.random_v(rng), (1, 3, 1))
    assert lk.difference(tw.model, q, q[0, 0]).shape == (4, 1, tw.nv)
    dq, dv = lk.integrate_jacobians(tw.model, q, v)
    d0, d1 = lk.difference_jacobians(tw.model, q, q[0])
    assert dq.shape == dv.shape == (4, 3, tw.nv, tw.nv) and d0.shape == d1.shape == (4, 1, tw.nv, tw.nv)
    dq[...] = np.nan  # the two outputs do not overlap
    d0[...] = np.nan
    assert np.all(np.isfinite(dv)) and np.all(np.isfinite(d1))
    # dt defaults to 1.
    assert np.array_equal(lk.integrate_jacobians(tw.model, q[0, 0], v[0, 0])[1], lk.integrate_jacobians(tw.model, q[0, 0], v[0, 0], 1.0)[1])


def _bad_quaternion_row(q):
    bad = np.tile(q, (3, 1))
    bad[2] = _bad_q(q)
    return bad


BAD_CALLS = [
    ("difference q0 short", lambda m, q, v: lk.difference(m, q[:-1], q), ("q0",)),
    ("difference q1 nan", lambda m, q, v: lk.difference(m, q, _with_nan(q, 1)), ("q1",)),
    ("difference q1 quat", lambda m, q, v: lk.difference(m, q, _bad_q(q)), ("q1",)),
    ("difference q0 quat in a batch", lambda m, q, v: lk.difference(m, _bad_quaternion_row(q), q), ("q0",)),
    ("difference batch mismatch", lambda m, q, v: lk.difference(m, np.tile(q, (3, 1)), np.tile(q, (4, 1))), ("q0", "q1")),
    ("difference q0 string", lambda m, q, v: lk.difference(m, "abc", q), ("q0",)),
    ("integrate_jacobians q quat", lambda m, q, v: lk.integrate_jacobians(m, _bad_q(q), v), ("q",)),
    ("integrate_jacobians q short", lambda m, q, v: lk.integrate_jacobians(m, q[:-1], v), ("q",)),
    ("integrate_jacobians v nan", lambda m, q, v: lk.integrate_jacobians(m, q, _with_nan(v, 4)), ("v",)),
    ("integrate_jacobians v long", lambda m, q, v: lk.integrate_jacobians(m, q, np.append(v, 0.0)), ("v",)),
    ("integrate_jacobians dt inf", lambda m, q, v: lk.integrate_jacobians(m, q, v, np.inf), ("dt",)),
    ("difference_jacobians q0 quat", lambda m, q, v: lk.difference_jacobians(m, _bad_q(q), q), ("q0",)),
    ("difference_jacobians q1 nan", lambda m, q, v: lk.difference_jacobians(m, q, _with_nan(q, 8)), ("q1",)),
    ("difference_jacobians q1 2d wrong", lambda m, q, v: lk.difference_jacobians(m, q, np.zeros((2, len(q) + 1))), ("q1",)),
]


@pytest.mark.parametrize("case, call, names", BAD_CALLS, ids=[c[0] for c in BAD_CALLS])
def test_bad_call_raises(case, call, names):
    tw, rng = _floating_twin(), np.random.default_rng(9)
    q, v = tw.random_q(rng), tw.random_v(rng)
    with pytest.raises((ValueError, TypeError)) as info:
        call(tw.model, q, v)
    assert _mentions(str(info.value), names), f"{case}: message {str(info.value)!r} does not name {names}"
