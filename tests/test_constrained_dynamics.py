"""Contact-constrained dynamics, impacts, the reduced ODE and free rollouts, checked against physics that
does not reuse the code under test: finite differences of the contact points' motion, energy and momentum
balances, and the full constrained solve."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def random_tree(rng: np.random.Generator, n: int, floating: bool, chain: bool = False) -> lk.Model:
    body = lambda: lk.MassProperties.solid_box(  # noqa: E731
        rng.uniform(0.2, 2.0), rng.uniform(0.05, 0.4, 3), center=rng.uniform(-0.2, 0.2, 3), rotation=random_rotation(rng)
    )
    model = lk.Model(floating_base=floating, base=body())
    for i in range(1, n + 1):
        parent = i - 1 if chain else int(rng.integers(0, i))
        placement = (random_rotation(rng), rng.uniform(-0.3, 0.3, 3))
        if rng.uniform() < 0.2:
            model.add_prismatic(parent, rng.normal(size=3), placement, body())
        else:
            model.add_revolute(parent, rng.normal(size=3), placement, body())
    return model


def random_state(rng: np.random.Generator, model: lk.Model, speed: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    q = rng.uniform(-np.pi, np.pi, model.nq)
    if model.floating_base:
        quaternion = rng.normal(size=4)
        q[3:7] = quaternion / np.linalg.norm(quaternion)
    return q, rng.uniform(-speed, speed, model.nv)


def random_contacts(rng: np.random.Generator, model: lk.Model, k: int) -> list[tuple[int, np.ndarray]]:
    bodies = rng.choice(np.arange(1, model.nbodies), size=k, replace=False)
    return [(int(b), rng.uniform(-0.2, 0.2, 3)) for b in bodies]


def point_position(model: lk.Model, q: np.ndarray, body: int, point: np.ndarray) -> np.ndarray:
    pose = lk.forward_kinematics(model, q)[body]
    return pose[:3, :3] @ point + pose[:3, 3]


def point_velocity(model, q, v, body, point):
    return lk.jacobian(model, q, body, point)[:3] @ v


def independent_contact_case(
    seed: int, floating: bool, min_bodies: int, contact_counts: tuple[int, int], speed: float = 1.0
) -> tuple[lk.Model, np.ndarray, np.ndarray, np.ndarray, list[tuple[int, np.ndarray]]]:
    """A random tree of min_bodies..11 joints, state, torques and contacts (a count drawn from
    contact_counts, high end excluded) whose point Jacobians are independent: redundant contacts are
    tested separately, so hypothesis discards the draws that have them."""
    rng = np.random.default_rng(seed)
    model = random_tree(rng, int(rng.integers(min_bodies, 12)), floating)
    q, v = random_state(rng, model, speed)
    tau = rng.uniform(-2, 2, model.nv)
    contacts = random_contacts(rng, model, int(rng.integers(*contact_counts)))
    assume(np.linalg.matrix_rank(np.vstack([lk.jacobian(model, q, b, p)[:3] for b, p in contacts])) == 3 * len(contacts))
    return model, q, v, tau, contacts


seeds = st.integers(0, 2**32 - 1)


@examples(40)
@given(seed=seeds, floating=st.booleans())
def test_contact_points_do_not_accelerate(seed, floating):
    """Central differences of each contact point's velocity along (q, v, q̈) vanish to O(h²)."""
    model, q, v, tau, contacts = independent_contact_case(seed, floating, 4, (1, 3))
    jacobians = [lk.jacobian(model, q, b, p)[:3] for b, p in contacts]
    ddq, forces = lk.contact_dynamics(model, q, v, tau, contacts)
    assert forces.shape == (len(contacts), 3)

    # The constrained motion satisfies M q̈ + h = τ + Σ Jᵢᵀ fᵢ.
    generalized = sum(j.T @ f for j, f in zip(jacobians, forces))
    residual = lk.rnea(model, q, v, ddq) - tau - generalized
    assert np.abs(residual).max() <= 1e-8 * max(1.0, np.abs(tau).max(), np.abs(generalized).max())

    h = 1e-5
    for body, point in contacts:
        after = point_velocity(model, lk.integrate(model, q, v, h), v + h * ddq, body, point)
        before = point_velocity(model, lk.integrate(model, q, v, -h), v - h * ddq, body, point)
        acceleration = (after - before) / (2 * h)
        scale = 1.0 + np.abs(v).max() ** 2 + np.abs(ddq).max()
        assert np.abs(acceleration).max() <= 1e-5 * scale, acceleration


@examples(40)
@given(seed=seeds, floating=st.booleans())
def test_impact_stops_contact_points_and_never_adds_energy(seed, floating):
    model, q, v, _, contacts = independent_contact_case(seed, floating, 4, (1, 3), speed=2.0)
    v_plus, impulses = lk.impact(model, q, v, contacts)
    for body, point in contacts:
        assert np.abs(point_velocity(model, q, v_plus, body, point)).max() <= 1e-9 * (1 + np.abs(v).max())
    before, after = lk.kinetic_energy(model, q, v), lk.kinetic_energy(model, q, v_plus)
    assert after <= before * (1 + 1e-12)
    # The velocity jump is the impulses' doing: M (v⁺ − v⁻) = Σ Jᵢᵀ Λᵢ.
    jump = lk.crba(model, q) @ (v_plus - v)
    applied = sum(lk.jacobian(model, q, b, p)[:3].T @ f for (b, p), f in zip(contacts, impulses))
    assert np.abs(jump - applied).max() <= 1e-9 * max(1.0, np.abs(applied).max())


@examples(40)
@given(seed=seeds, floating=st.booleans())
def test_reduced_ode_agrees_with_the_constrained_solve(seed, floating):
    model, q, v, tau, contacts = independent_contact_case(seed, floating, 5, (1, 2))
    ddq, _ = lk.contact_dynamics(model, q, v, tau, contacts)
    reduced_ddq, independent, dependent, basis, mass, force, offset = lk.reduced_dynamics(model, q, v, tau, contacts)
    assert sorted(independent + dependent) == list(range(model.nv))
    assert len(dependent) == 3
    assert np.abs(reduced_ddq - ddq).max() <= 1e-8 * max(1.0, np.abs(ddq).max())
    # v = N v_I keeps the contact still, and the reduced mass matrix is Nᵀ M N.
    j = lk.jacobian(model, q, *contacts[0])[:3]
    assert np.abs(j @ basis).max() <= 1e-9 * max(1.0, np.abs(basis).max())
    m = lk.crba(model, q)
    assert np.allclose(mass, basis.T @ m @ basis, rtol=1e-10, atol=1e-12)
    assert np.allclose(np.linalg.solve(mass, force), reduced_ddq[independent], rtol=1e-8, atol=1e-10)


def test_a_box_on_four_feet_stands_still_on_redundant_contacts():
    """Twelve constraints on a 6-DoF body: the minimum-norm forces carry the weight, evenly by symmetry."""
    mass, size = 3.0, np.array([0.4, 0.2, 0.1])
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(mass, size))
    q = model.neutral()
    q[:3] = [0.3, -0.2, 0.05]
    corners = [np.array([sx * 0.2, sy * 0.1, -0.05]) for sx in (-1, 1) for sy in (-1, 1)]
    ddq, forces = lk.contact_dynamics(model, q, np.zeros(6), np.zeros(6), [(0, c) for c in corners])
    assert np.abs(ddq).max() <= 1e-12
    assert np.allclose(forces, [[0, 0, mass * -model.gravity[2] / 4]] * 4, rtol=1e-12, atol=1e-12)


def test_reduced_ode_accepts_chosen_independent_coordinates():
    rng = np.random.default_rng(3)
    model = random_tree(rng, 6, False, chain=True)
    q, v = random_state(rng, model)
    tau = rng.uniform(-1, 1, model.nv)
    contacts = [(6, np.array([0.1, 0.0, 0.0]))]
    ddq, _ = lk.contact_dynamics(model, q, v, tau, contacts)
    reduced = lk.reduced_dynamics(model, q, v, tau, contacts, independent=[0, 1, 2])
    assert reduced[1] == [0, 1, 2] and reduced[2] == [3, 4, 5]
    assert np.abs(reduced[0] - ddq).max() <= 1e-8 * max(1.0, np.abs(ddq).max())


def test_energy_is_conserved_by_rk4_over_five_seconds():
    """A free 20-link tree under gravity, no torques: RK4 at 1 kHz for 5 s drifts below 1e-6 relative."""
    rng = np.random.default_rng(20)
    model = random_tree(rng, 20, False)
    q, v = random_state(rng, model, speed=0.5)
    qs, vs = lk.free_rollout(model, q, v, dt=1e-3, steps=5000, method="rk4")
    energy = lk.kinetic_energy(model, qs, vs) + lk.potential_energy(model, qs)
    # Relative to the energy sloshing between kinetic and potential (the total's own scale is arbitrary).
    scale = np.ptp(lk.kinetic_energy(model, qs, vs))
    assert scale > 1.0
    drift = np.abs(energy - energy[0]).max() / scale
    assert drift < 1e-6, drift


def test_momentum_is_conserved_for_a_floating_base_without_gravity():
    rng = np.random.default_rng(5)
    model = random_tree(rng, 12, True)
    weightless = lk.Model(floating_base=True, base=model.body(0), gravity=[0, 0, 0])
    for i in range(1, model.nbodies):
        placement = model.placement(i)
        kind = model.joint_type(i)
        add = weightless.add_revolute if kind == "revolute" else weightless.add_prismatic
        add(model.parents[i], model.joint_axis(i), placement, model.body(i))
    q, v = random_state(rng, weightless, speed=1.0)
    tau = np.zeros(weightless.nv)
    rate = lk.centroidal_momentum_rate(weightless, q, v, lk.aba(weightless, q, v, tau))
    assert np.abs(rate).max() <= 1e-9 * max(1.0, np.abs(lk.centroidal_momentum(weightless, q, v)).max())
    qs, vs = lk.free_rollout(weightless, q, v, dt=1e-3, steps=2000, method="rk4")
    momentum = lk.centroidal_momentum(weightless, qs, vs)
    assert np.abs(momentum - momentum[0]).max() <= 1e-6 * np.abs(momentum[0]).max()


def test_semi_implicit_euler_is_first_order():
    """Halving dt halves the error against an RK4 reference."""
    rng = np.random.default_rng(8)
    model = random_tree(rng, 5, False, chain=True)
    q, v = random_state(rng, model, speed=0.5)
    reference, _ = lk.free_rollout(model, q, v, dt=1e-4, steps=2000, method="rk4")
    errors = []
    for dt in (2e-3, 1e-3):
        steps = int(round(0.2 / dt))
        qs, _ = lk.free_rollout(model, q, v, dt=dt, steps=steps, method="semi_implicit_euler")
        errors.append(np.abs(qs[-1] - reference[-1]).max())
    assert 1.6 < errors[0] / errors[1] < 2.5, errors


def test_bad_contact_and_rollout_input_names_the_argument():
    model = random_tree(np.random.default_rng(1), 3, False)
    q, v, tau = np.zeros(model.nq), np.zeros(model.nv), np.zeros(model.nv)
    with pytest.raises(ValueError, match="contacts"):
        lk.contact_dynamics(model, q, v, tau, [])
    with pytest.raises(IndexError, match="body"):
        lk.contact_dynamics(model, q, v, tau, [(17, [0, 0, 0])])
    with pytest.raises(ValueError, match="contacts"):
        lk.impact(model, q, v, [(1, [np.nan, 0, 0])])
    with pytest.raises(TypeError, match="contacts"):
        lk.impact(model, q, v, [1, 2])
    with pytest.raises(ValueError, match="dt"):
        lk.free_rollout(model, q, v, dt=0.0, steps=3)
    with pytest.raises(ValueError, match="tau"):
        lk.free_rollout(model, q, v, dt=1e-3, steps=3, tau=np.ones(model.nv + 1))
    with pytest.raises(ValueError, match="method"):
        lk.free_rollout(model, q, v, dt=1e-3, steps=3, method="euler")
    with pytest.raises(ValueError, match="independent"):
        lk.reduced_dynamics(model, q, v, tau, [(1, [0, 0, 0])], independent=[9])


def test_a_singular_mass_matrix_is_a_numerical_error():
    # The second link carries no inertia: M is singular, a RuntimeError (not a ValueError: no argument is bad).
    model = lk.Model()
    first = model.add_revolute(0, [0, 1, 0], body=lk.MassProperties(1.0, [0, 0, -0.5], np.eye(3) * 0.01))
    model.add_revolute(first, [1, 0, 0], placement=(np.eye(3), [0, 0, -1]), body=lk.MassProperties.zero())
    q, v, tau = np.zeros(model.nq), np.zeros(model.nv), np.zeros(model.nv)
    assert np.linalg.eigvalsh(lk.crba(model, q)).min() <= 1e-15
    for call in (lambda: lk.contact_dynamics(model, q, v, tau, [(1, [0, 0, -1])]), lambda: lk.impact(model, q, v, [(1, [0, 0, -1])])):
        with pytest.raises(RuntimeError, match="singular"):
            call()
