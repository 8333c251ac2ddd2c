"""The derivatives of the contact dynamics and of impacts (``lk.contact_dynamics_derivatives``,
``lk.impact_derivatives``).

Against Pinocchio's ``computeConstraintDynamicsDerivatives`` and ``computeImpulseDynamicsDerivatives`` (3-D contacts in
LOCAL_WORLD_ALIGNED, no proximal damping, no restitution) on random trees with every joint kind; against five-point
central differences of legkit's own ``contact_dynamics`` and ``impact``; and in closed form on a body held at its
centre of mass. Both references lose digits with the conditioning of the contacts (J M^-1 J^T), so the tolerance
grows with its condition number beyond 1e6, as in tests/test_urdf_robots.py.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given

import legkit as lk
from conftest import examples
from robots import Twin, rngs, twins
from test_derivatives import FD_RTOL, coordinate_differences, tangent_differences
from test_dynamics_pinocchio import RTOL, note_case, state


def random_contacts(tw: Twin, rng: np.random.Generator) -> list[tuple[int, np.ndarray]]:
    """One to three points on distinct random bodies, at most nv / 3 of them."""
    count = min(int(rng.integers(1, 4)), tw.nv // 3, tw.nbodies)
    bodies = rng.choice(tw.nbodies, size=count, replace=False)
    return [(int(b), rng.uniform(-0.5, 0.5, size=3)) for b in bodies]


def condition(tw: Twin, q: np.ndarray, contacts) -> float:
    j = np.vstack([lk.jacobian(tw.model, q, b, p)[:3] for b, p in contacts])
    schur = j @ np.linalg.solve(lk.crba(tw.model, q), j.T)
    eigenvalues = np.linalg.eigvalsh(schur)
    return float(eigenvalues[-1] / eigenvalues[0]) if eigenvalues[0] > 0.0 else np.inf


def assert_close(got, want, rtol: float, what: str) -> None:
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape, f"{what}: shape {got.shape} != {want.shape}"
    scale = max(1.0, float(np.abs(want).max(initial=0.0)))
    error = float(np.abs(got - want).max(initial=0.0))
    assert error <= rtol * scale, f"{what}: max error {error:.3e} > {rtol:g} * {scale:.3e}"


def pin_contacts(tw: Twin, contacts):
    models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    for body, point in contacts:
        placement = tw.body_in_joint[body] * pin.SE3(np.eye(3), point)
        models.append(pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, tw.pin_model, tw.body_joint[body], placement, pin.LOCAL_WORLD_ALIGNED))
    for model in models:
        datas.append(model.createData())
    return models, datas


def independent_case(tw: Twin, rng: np.random.Generator):
    """A state and contacts whose forces are unique (J of full row rank, as the derivatives need); else the example is
    discarded."""
    q, v, _ = state(tw, rng)
    contacts = random_contacts(tw, rng)
    assume(contacts)
    cond = condition(tw, q, contacts)
    assume(cond < 1e10)
    note_case(tw, q=q, v=v)
    return q, v, contacts, max(1.0, cond / 1e6)


@examples(60)
@given(tw=twins(max_bodies=40), rng=rngs())
def test_contact_dynamics_derivatives_match_pinocchio(tw: Twin, rng):
    q, v, contacts, loss = independent_case(tw, rng)
    tau = rng.uniform(-20.0, 20.0, size=tw.nv)
    models, datas = pin_contacts(tw, contacts)
    data = tw.data()
    settings = pin.ProximalSettings(1e-14, 0.0, 1)
    pin.initConstraintDynamics(tw.pin_model, data, models, datas)
    pin.constraintDynamics(tw.pin_model, data, tw.q_pin(q), tw.v_pin(v), tw.v_pin(tau), models, datas, settings)
    pin.computeConstraintDynamicsDerivatives(tw.pin_model, data, models, datas, settings)
    got = lk.contact_dynamics_derivatives(tw.model, q, v, tau, contacts)
    k = len(contacts)
    for g, name in zip(got[:3], ("ddq_dq", "ddq_dv", "ddq_dtau")):
        assert_close(g, tw.m_lk(np.array(getattr(data, name))), RTOL * loss, name)
    for g, name in zip(got[3:], ("dlambda_dq", "dlambda_dv", "dlambda_dtau")):
        assert_close(g, tw.cols_lk(np.array(getattr(data, name))).reshape(k, 3, tw.nv), RTOL * loss, name)


# Without spherical joints: on some trees with one, legkit and Pinocchio differ by up to 3e-7 (relative) at a contact
# condition number below 1e8, where central differences (5e-5 off for both) cannot tell which is nearer; the slopes
# test below covers ball joints.
@examples(60)
@given(tw=twins(max_bodies=40, ball=False), rng=rngs())
def test_impact_derivatives_match_pinocchio(tw: Twin, rng):
    """Pinocchio's impulse-dynamics ddq_dv is the derivative of the velocity change v+ - v, legkit's that of v+."""
    q, v, contacts, loss = independent_case(tw, rng)
    models, datas = pin_contacts(tw, contacts)
    data = tw.data()
    settings = pin.ProximalSettings(1e-14, 0.0, 1)
    pin.initConstraintDynamics(tw.pin_model, data, models, datas)
    pin.impulseDynamics(tw.pin_model, data, tw.q_pin(q), tw.v_pin(v), models, datas, 0.0, settings)
    pin.computeImpulseDynamicsDerivatives(tw.pin_model, data, models, datas, 0.0, settings)
    v_dq, v_dv, impulses_dq, impulses_dv = lk.impact_derivatives(tw.model, q, v, contacts)
    k = len(contacts)
    assert_close(v_dq, tw.m_lk(np.array(data.ddq_dq)), RTOL * loss, "v+/dq")
    assert_close(v_dv, tw.m_lk(np.array(data.ddq_dv)) + np.eye(tw.nv), RTOL * loss, "v+/dv")
    assert_close(impulses_dq, tw.cols_lk(np.array(data.dlambda_dq)).reshape(k, 3, tw.nv), RTOL * loss, "impulses/dq")
    assert_close(impulses_dv, tw.cols_lk(np.array(data.dlambda_dv)).reshape(k, 3, tw.nv), RTOL * loss, "impulses/dv")


def slopes(m: lk.Model, f, q: np.ndarray, *vectors: np.ndarray) -> list[np.ndarray]:
    """Central differences of f(q, *vectors) along q (tangent space) and along each vector."""
    out = [tangent_differences(m, lambda x: f(x, *vectors), q)]
    for i, x0 in enumerate(vectors):
        out.append(coordinate_differences(lambda x: f(q, *vectors[:i], x, *vectors[i + 1 :]), x0))  # noqa: B023 (used at once)
    return out


@examples(30)
@given(tw=twins(max_bodies=20), rng=rngs())
def test_contact_derivatives_are_the_slopes_of_contact_dynamics_and_impact(tw: Twin, rng):
    q, v, contacts, loss = independent_case(tw, rng)
    tau = rng.uniform(-20.0, 20.0, size=tw.nv)
    m, rtol = tw.model, FD_RTOL * loss
    got = lk.contact_dynamics_derivatives(m, q, v, tau, contacts)
    want = slopes(m, lambda *x: lk.contact_dynamics(m, *x, contacts)[0], q, v, tau) + slopes(
        m, lambda *x: lk.contact_dynamics(m, *x, contacts)[1], q, v, tau
    )
    for g, w, name in zip(got, want, ("ddq_dq", "ddq_dv", "ddq_dtau", "forces_dq", "forces_dv", "forces_dtau")):
        assert_close(g, w, rtol, name)
    got = lk.impact_derivatives(m, q, v, contacts)
    want = slopes(m, lambda *x: lk.impact(m, *x, contacts)[0], q, v) + slopes(m, lambda *x: lk.impact(m, *x, contacts)[1], q, v)
    for g, w, name in zip(got, want, ("v+/dq", "v+/dv", "impulses/dq", "impulses/dv")):
        assert_close(g, w, rtol, name)


def held_box() -> tuple[lk.Model, np.ndarray, list]:
    """A free box (2 kg) held at its centre of mass, turned by 0.5 rad about z."""
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.3, 0.2, 0.1]))
    q = np.r_[0.1, 0.2, 0.3, 0.0, 0.0, np.sin(0.25), np.cos(0.25)]
    return model, q, [(0, np.zeros(3))]


def test_a_body_held_at_its_centre_of_mass_in_closed_form():
    """Held at its COM, the box's linear motion stops and its rotation goes on as if free. At rest, m a = tau_lin +
    m R^T g + R^T f = 0 gives f = -R tau_lin - m g: df/dtau = [-R, 0]; the angular accelerations are I^-1 tau_ang; an
    impact cancels the linear velocity (dv+/dv = diag(0, 0, 0, 1, 1, 1)) with impulses -m R v_lin."""
    model, q, held = held_box()
    m, rotation = 2.0, np.array([[np.cos(0.5), -np.sin(0.5), 0.0], [np.sin(0.5), np.cos(0.5), 0.0], [0.0, 0.0, 1.0]])
    _, _, ddq_dtau, _, _, forces_dtau = lk.contact_dynamics_derivatives(model, q, np.zeros(6), np.zeros(6), held)
    inertia = m / 12.0 * np.diag([0.2**2 + 0.1**2, 0.3**2 + 0.1**2, 0.3**2 + 0.2**2])
    assert np.allclose(forces_dtau[0], np.hstack([-rotation, np.zeros((3, 3))]), rtol=0, atol=1e-12)
    assert np.allclose(ddq_dtau, np.block([[np.zeros((3, 6))], [np.zeros((3, 3)), np.linalg.inv(inertia)]]), rtol=0, atol=1e-10)
    v = np.array([0.3, -0.2, 0.5, 0.1, 0.2, -0.4])
    _, v_dv, _, impulses_dv = lk.impact_derivatives(model, q, v, held)
    assert np.allclose(v_dv, np.diag([0.0, 0.0, 0.0, 1.0, 1.0, 1.0]), rtol=0, atol=1e-12)
    assert np.allclose(impulses_dv[0], np.hstack([-m * rotation, np.zeros((3, 3))]), rtol=0, atol=1e-12)


def test_dependent_contacts_and_bad_arguments_are_refused():
    model, q, held = held_box()
    zeros = np.zeros(6)
    twice = held + [(0, np.zeros(3))]  # the same point twice: its forces are not unique
    with pytest.raises(ValueError, match="not independent"):
        lk.contact_dynamics_derivatives(model, q, zeros, zeros, twice)
    with pytest.raises(ValueError, match="not independent"):
        lk.impact_derivatives(model, q, zeros, twice)
    with pytest.raises(ValueError, match="contacts"):
        lk.contact_dynamics_derivatives(model, q, zeros, zeros, [])
    with pytest.raises(ValueError, match="tau"):
        lk.contact_dynamics_derivatives(model, q, zeros, np.zeros(5), held)
    shapes = [x.shape for x in lk.contact_dynamics_derivatives(model, np.tile(q, (2, 1)), zeros, zeros, held)]
    assert shapes == [(2, 6, 6)] * 3 + [(2, 1, 3, 6)] * 3
