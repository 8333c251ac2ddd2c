"""The derivatives of the contact dynamics and of impacts (``lk.contact_dynamics_derivatives``,
``lk.impact_derivatives``).

Against Pinocchio's ``computeConstraintDynamicsDerivatives`` and ``computeImpulseDynamicsDerivatives`` (CONTACT_3D
contacts, ``dim=3``, and CONTACT_6D ones, ``dim=6``, in LOCAL_WORLD_ALIGNED, no proximal damping, no restitution) on
random trees with every joint kind and on the biped standing on both flat feet; against five-point central differences
of legkit's own ``contact_dynamics`` and ``impact``; and in closed form on a body held at its centre of mass. Both
references lose digits with the conditioning of the contacts (J M^-1 J^T), so the tolerance grows with its condition
number beyond 1e6, as in tests/test_urdf_robots.py.
"""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given

import legkit as lk
from conftest import examples
from legkit.robots.biped import build_biped
from robots import Twin, rngs, twins
from test_derivatives import FD_RTOL, coordinate_differences, settled, tangent_differences
from test_dynamics_pinocchio import RTOL, note_case, state
from test_urdf_robots import Twin as UrdfTwin

CONTACT_TYPE = {3: pin.ContactType.CONTACT_3D, 6: pin.ContactType.CONTACT_6D}


def random_contacts(tw: Twin, rng: np.random.Generator, dim: int, spare: int = 0) -> list[tuple[int, np.ndarray]]:
    """One to three contacts on distinct random bodies, at most (nv - spare) / dim of them."""
    count = max(0, min(int(rng.integers(1, 4)), (tw.nv - spare) // dim, tw.nbodies))
    bodies = rng.choice(tw.nbodies, size=count, replace=False)
    return [(int(b), rng.uniform(-0.5, 0.5, size=3)) for b in bodies]


def condition(model: lk.Model, q: np.ndarray, contacts, dim: int) -> float:
    j = np.vstack([lk.jacobian(model, q, b, p)[:dim] for b, p in contacts])
    schur = j @ np.linalg.solve(lk.crba(model, q), j.T)
    eigenvalues = np.linalg.eigvalsh(schur)
    return float(eigenvalues[-1] / eigenvalues[0]) if eigenvalues[0] > 0.0 else np.inf


def assert_close(got, want, rtol: float, what: str) -> None:
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape, f"{what}: shape {got.shape} != {want.shape}"
    scale = max(1.0, float(np.abs(want).max(initial=0.0)))
    error = float(np.abs(got - want).max(initial=0.0))
    assert error <= rtol * scale, f"{what}: max error {error:.3e} > {rtol:g} * {scale:.3e}"


def pin_contacts(pin_model: pin.Model, placements, dim: int):
    """Pinocchio's contact models for (joint, placement in the joint's frame) pairs, and their datas."""
    models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    for joint, placement in placements:
        models.append(pin.RigidConstraintModel(CONTACT_TYPE[dim], pin_model, joint, placement, pin.LOCAL_WORLD_ALIGNED))
    for model in models:
        datas.append(model.createData())
    return models, datas


def twin_contacts(tw: Twin, contacts, dim: int):
    return pin_contacts(tw.pin_model, [(tw.body_joint[b], tw.body_in_joint[b] * pin.SE3(np.eye(3), p)) for b, p in contacts], dim)


def independent_case(tw: Twin, rng: np.random.Generator, dim: int, spare: int = 0):
    """A state and contacts whose forces are unique (J of full row rank, as the derivatives need), leaving at least
    `spare` coordinates free; else the example is discarded."""
    q, v, _ = state(tw, rng)
    contacts = random_contacts(tw, rng, dim, spare)
    assume(contacts)
    cond = condition(tw.model, q, contacts, dim)
    assume(cond < 1e10)
    note_case(tw, q=q, v=v)
    return q, v, contacts, max(1.0, cond / 1e6)


SETTINGS = pin.ProximalSettings(1e-14, 0.0, 1)


def pin_constraint_derivatives(pin_model: pin.Model, data, models, datas, q, v, tau) -> list[np.ndarray]:
    """Pinocchio's ddq_dq, ddq_dv, ddq_dtau, dlambda_dq, dlambda_dv, dlambda_dtau (its velocity order)."""
    pin.initConstraintDynamics(pin_model, data, models, datas)
    pin.constraintDynamics(pin_model, data, q, v, tau, models, datas, SETTINGS)
    pin.computeConstraintDynamicsDerivatives(pin_model, data, models, datas, SETTINGS)
    names = ("ddq_dq", "ddq_dv", "ddq_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau")
    return [np.array(getattr(data, name)) for name in names]


def pin_impact_derivatives(pin_model: pin.Model, data, models, datas, q, v) -> list[np.ndarray]:
    """Pinocchio's impulse derivatives as legkit's: dv+/dq, dv+/dv, dimpulses/dq, dimpulses/dv (its velocity order;
    its ddq_dv is the derivative of the velocity change v+ - v, legkit's that of v+)."""
    pin.initConstraintDynamics(pin_model, data, models, datas)
    pin.impulseDynamics(pin_model, data, q, v, models, datas, 0.0, SETTINGS)
    pin.computeImpulseDynamicsDerivatives(pin_model, data, models, datas, 0.0, SETTINGS)
    return [np.array(data.ddq_dq), np.array(data.ddq_dv) + np.eye(pin_model.nv), np.array(data.dlambda_dq), np.array(data.dlambda_dv)]


def check_against_pinocchio(tw: Twin, rng: np.random.Generator, dim: int) -> None:
    """With a coordinate left free: contacts that hold every coordinate (6 k = nv, as one held free body) leave q̈ to
    the kinematics alone, and each entry of the KKT inverse's q̈ blocks is then a cancellation to zero in which both
    libraries keep about 1e-8 of the terms' size (their difference, 2.5e-8 on such a body, is rounding; the
    central-difference test below covers them)."""
    q, v, contacts, loss = independent_case(tw, rng, dim, spare=1)
    tau = rng.uniform(-20.0, 20.0, size=tw.nv)
    models, datas = twin_contacts(tw, contacts, dim)
    want = pin_constraint_derivatives(tw.pin_model, tw.data(), models, datas, tw.q_pin(q), tw.v_pin(v), tw.v_pin(tau))
    got = lk.contact_dynamics_derivatives(tw.model, q, v, tau, contacts, dim=dim)
    k = len(contacts)
    for g, w, name in zip(got[:3], want[:3], ("ddq_dq", "ddq_dv", "ddq_dtau")):
        assert_close(g, tw.m_lk(w), RTOL * loss, name)
    for g, w, name in zip(got[3:], want[3:], ("dlambda_dq", "dlambda_dv", "dlambda_dtau")):
        assert_close(g, tw.cols_lk(w).reshape(k, dim, tw.nv), RTOL * loss, name)
    models, datas = twin_contacts(tw, contacts, dim)
    want = pin_impact_derivatives(tw.pin_model, tw.data(), models, datas, tw.q_pin(q), tw.v_pin(v))
    got = lk.impact_derivatives(tw.model, q, v, contacts, dim=dim)
    for g, w, name in zip(got[:2], want[:2], ("v+/dq", "v+/dv")):
        assert_close(g, tw.m_lk(w), RTOL * loss, name)
    for g, w, name in zip(got[2:], want[2:], ("impulses/dq", "impulses/dv")):
        assert_close(g, tw.cols_lk(w).reshape(k, dim, tw.nv), RTOL * loss, name)


# Without spherical joints: below one, Pinocchio's frame-acceleration derivatives are not the slopes of its own frame
# acceleration (O(1) off, in WORLD and LOCAL_WORLD_ALIGNED), and its impact derivatives differed from legkit's by up to
# 3e-7 at contact condition numbers below 1e8, where central differences (5e-5 off for both) cannot tell which is
# nearer; the slopes tests below cover ball joints.
@examples(60)
@given(tw=twins(max_bodies=40, ball=False), rng=rngs())
def test_point_contact_derivatives_match_pinocchio(tw: Twin, rng):
    check_against_pinocchio(tw, rng, 3)


@examples(60)
@given(tw=twins(max_bodies=40, floating=True, ball=False), rng=rngs())
def test_frame_contact_derivatives_match_pinocchio(tw: Twin, rng):
    """dim=6 (CONTACT_6D) on floating trees, which have the six coordinates a held frame takes."""
    check_against_pinocchio(tw, rng, 6)


def test_the_biped_on_both_flat_feet_matches_pinocchio():
    """The biped's URDF loaded by both libraries, both feet held flat (dim=6) at their soles' centres, or at a point
    each (dim=3), at random states."""
    biped = build_biped()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)
        model = lk.Model.from_urdf(biped.to_urdf(), floating_base=True)
    reference = pin.buildModelFromXML(biped.to_urdf(), pin.JointModelFreeFlyer())
    twin = UrdfTwin(model, reference)
    sole = np.array([0.05, 0.0, -biped.parameters.ankle_height])
    feet = [model.names.index(f"{side}_foot") for side in ("l", "r")]
    frames = [reference.frames[reference.getFrameId(model.names[b], pin.FrameType.BODY)] for b in feet]
    placements = [(f.parentJoint, f.placement * pin.SE3(np.eye(3), sole)) for f in frames]
    contacts = [(b, sole) for b in feet]
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, q_pin = twin.state(rng)
        v, tau = rng.normal(size=model.nv), rng.normal(scale=5.0, size=model.nv)
        for dim in (3, 6):
            loss = max(1.0, condition(model, q, contacts, dim) / 1e6)
            models, datas = pin_contacts(reference, placements, dim)
            want = pin_constraint_derivatives(reference, reference.createData(), models, datas, q_pin, v, tau)
            got = lk.contact_dynamics_derivatives(model, q, v, tau, contacts, dim=dim)
            ddq, forces = lk.contact_dynamics(model, q, v, tau, contacts, dim=dim)
            models, datas = pin_contacts(reference, placements, dim)
            data = reference.createData()
            pin.initConstraintDynamics(reference, data, models, datas)
            want_ddq = pin.constraintDynamics(reference, data, q_pin, v, tau, models, datas, SETTINGS)
            assert_close(ddq, want_ddq, RTOL * loss, f"dim {dim}: ddq")
            assert_close(forces.ravel(), np.array(data.lambda_c), RTOL * loss, f"dim {dim}: forces")
            for g, w, name in zip(got, want, ("ddq_dq", "ddq_dv", "ddq_dtau", "dlambda_dq", "dlambda_dv", "dlambda_dtau")):
                w = w if name.startswith("ddq") else np.reshape(w, (2, dim, model.nv))
                assert_close(g, w, RTOL * loss, f"dim {dim}: {name}")
            models, datas = pin_contacts(reference, placements, dim)
            want = pin_impact_derivatives(reference, reference.createData(), models, datas, q_pin, v)
            got = lk.impact_derivatives(model, q, v, contacts, dim=dim)
            for g, w, name in zip(got, want, ("v+/dq", "v+/dv", "impulses/dq", "impulses/dv")):
                w = w if name.startswith("v+") else np.reshape(w, (2, dim, model.nv))
                assert_close(g, w, RTOL * loss, f"dim {dim}: {name}")


def slopes(m: lk.Model, f, q: np.ndarray, *vectors: np.ndarray) -> list[np.ndarray]:
    """Central differences of f(q, *vectors) along q (tangent space) and along each vector, each at its settled step
    (`settled`: the contacts' conditioning and the trees' depth leave no one step right for every case)."""
    out = [settled(lambda h: tangent_differences(m, lambda x: f(x, *vectors), q, h))]
    for i, x0 in enumerate(vectors):
        out.append(settled(lambda h: coordinate_differences(lambda x: f(q, *vectors[:i], x, *vectors[i + 1 :]), x0, h)))  # noqa: B023
    return out


def check_slopes(tw: Twin, rng: np.random.Generator, dim: int) -> None:
    """With a coordinate left free, as `check_against_pinocchio`."""
    q, v, contacts, loss = independent_case(tw, rng, dim, spare=1)
    tau = rng.uniform(-20.0, 20.0, size=tw.nv)
    m, rtol = tw.model, FD_RTOL * loss
    got = lk.contact_dynamics_derivatives(m, q, v, tau, contacts, dim=dim)
    want = slopes(m, lambda *x: lk.contact_dynamics(m, *x, contacts, dim=dim)[0], q, v, tau) + slopes(
        m, lambda *x: lk.contact_dynamics(m, *x, contacts, dim=dim)[1], q, v, tau
    )
    for g, w, name in zip(got, want, ("ddq_dq", "ddq_dv", "ddq_dtau", "forces_dq", "forces_dv", "forces_dtau")):
        assert_close(g, w, rtol, name)
    got = lk.impact_derivatives(m, q, v, contacts, dim=dim)
    want = slopes(m, lambda *x: lk.impact(m, *x, contacts, dim=dim)[0], q, v) + slopes(m, lambda *x: lk.impact(m, *x, contacts, dim=dim)[1], q, v)
    for g, w, name in zip(got, want, ("v+/dq", "v+/dv", "impulses/dq", "impulses/dv")):
        assert_close(g, w, rtol, name)


@examples(30)
@given(tw=twins(max_bodies=20), rng=rngs())
def test_point_contact_derivatives_are_the_slopes_of_contact_dynamics_and_impact(tw: Twin, rng):
    check_slopes(tw, rng, 3)


@examples(30)
@given(tw=twins(max_bodies=20, floating=True), rng=rngs())
def test_frame_contact_derivatives_are_the_slopes_of_contact_dynamics_and_impact(tw: Twin, rng):
    check_slopes(tw, rng, 6)


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
    with pytest.raises(ValueError, match="dim"):
        lk.contact_dynamics_derivatives(model, q, zeros, zeros, held, dim=4)
    shapes = [x.shape for x in lk.contact_dynamics_derivatives(model, np.tile(q, (2, 1)), zeros, zeros, held)]
    assert shapes == [(2, 6, 6)] * 3 + [(2, 1, 3, 6)] * 3
    shapes = [x.shape for x in lk.impact_derivatives(model, np.tile(q, (2, 1)), zeros, held, dim=6)]
    assert shapes == [(2, 6, 6)] * 2 + [(2, 1, 6, 6)] * 2


@pytest.mark.parametrize("call", [lk.contact_dynamics_derivatives, lk.contact_dynamics])
def test_contacts_too_many_to_hold_are_a_memory_error(call):
    """300,000 constraint rows ask for a 720 GB Schur complement: refused as a MemoryError naming the contacts, not an
    abort; the model still works afterwards."""
    model, q, held = held_box()
    zeros = np.zeros(6)
    with pytest.raises(MemoryError, match="contacts"):
        call(model, q, zeros, zeros, held * 100_000)
    assert np.all(np.isfinite(lk.contact_dynamics_derivatives(model, q, zeros, zeros, held)[0]))
