"""Differential tests of legkit's rigid-body dynamics against Pinocchio.

Every property builds a random kinematic tree twice (tests/robots.py: a legkit model and its exact
Pinocchio twin) and compares legkit with Pinocchio at 1e-9 relative,
    max|got - want| <= 1e-9 * max(1, max|want|).
Pinocchio's joints are in depth-first order, legkit's in body order; the twin converts q, v and results.

Also here: bit-for-bit agreement of batched calls (B=5, and B=300 for the multithreaded path) with
per-row calls, NumPy-style broadcasting, the gravity option, two Pinocchio-free self-consistency checks
(ABA == CRBA^-1 (tau - rnea(q, v, 0)) and minv @ crba == I), and bad-input handling.

Quantities that count bodies welded to a fixed base (centre of mass, subtree mass properties, centroidal
momentum, potential energy) are compared on models whose welded bodies are massless: Pinocchio never
counts them and legkit's convention for them is not specified here.
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given, note
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from robots import Twin, body_counts, build_twin, rngs, twins

RTOL = 1e-9
FRAMES = {
    "local": pin.ReferenceFrame.LOCAL,
    "world": pin.ReferenceFrame.WORLD,
    "local_world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
}


def fast(n: int):
    return examples(n)


def assert_close(got, want, what: str = "") -> None:
    got = np.asarray(got, dtype=np.float64)
    want = np.asarray(want, dtype=np.float64)
    assert got.shape == want.shape, f"{what}: shape {got.shape} != expected {want.shape}"
    assert np.all(np.isfinite(got)), f"{what}: non-finite values in {got}"
    scale = max(1.0, float(np.abs(want).max(initial=0.0)))
    err = float(np.abs(got - want).max(initial=0.0))
    assert err <= RTOL * scale, f"{what}: max error {err:.3e} > {RTOL:g} * {scale:.3e}\ngot\n{got}\nexpected\n{want}"


def note_case(tw: Twin, **arrays) -> None:
    note(tw.describe())
    for k, a in arrays.items():
        if a is not None:  # an optional argument the case leaves out
            note(f"{k} = np.array({np.asarray(a).tolist()!r})")


def pin_f_ext(tw: Twin, f) -> list:
    """Pinocchio's trailing fext argument for legkit's external forces f (nbodies, 6): none when f is None."""
    return [] if f is None else [tw.pin_fext(f)]


def pin_sym(m: np.ndarray) -> np.ndarray:
    """Pinocchio fills (at least) the upper triangle of M and Minv."""
    m = np.array(m, dtype=np.float64)
    return np.triu(m) + np.triu(m, 1).T


def state(tw: Twin, rng: np.random.Generator):
    return tw.random_q(rng), tw.random_v(rng), tw.random_v(rng)


def dynamics_case(tw: Twin, rng: np.random.Generator, with_f_ext: bool, given: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """A random case of inverse (given "a": q, v, a) or forward (given "tau": q, v, tau) dynamics, with external
    forces or None, noted for hypothesis' report."""
    q, v, a = state(tw, rng)
    given_value = a if given == "a" else rng.uniform(-20.0, 20.0, size=tw.nv)
    f = tw.random_f_ext(rng) if with_f_ext else None
    note_case(tw, q=q, v=v, **{given: given_value}, f_ext=f)
    return q, v, given_value, f


# --------------------------------------------------------------------------------------------------
# Model bookkeeping
# --------------------------------------------------------------------------------------------------


@fast(60)
@given(twins())
def test_model_layout(tw: Twin):
    m = tw.model
    nv_joints = sum({"revolute": 1, "prismatic": 1, "helical": 1, "spherical": 3}.get(k, 0) for k in tw.kinds)
    nq_joints = nv_joints + len(tw.quaternions)
    assert m.nv == nv_joints + (6 if tw.floating else 0)
    assert m.nq == nq_joints + (7 if tw.floating else 0)
    assert m.nbodies == tw.nbodies
    assert list(m.parents) == tw.parents
    assert list(m.names) == ["base"] + [f"b{i}" for i in range(1, tw.nbodies)]
    assert m.floating_base == tw.floating
    for i, kind in enumerate(tw.kinds):
        if kind != "base":
            assert m.joint_type(i) == kind
        if kind in ("revolute", "prismatic", "helical"):
            assert np.allclose(m.joint_axis(i), tw.axes[i] / np.linalg.norm(tw.axes[i]), rtol=0, atol=1e-15)
            assert m.joint_pitch(i) == (tw.pitches[i] if kind == "helical" else None)
        if kind in ("revolute", "prismatic", "helical", "spherical"):
            assert m.idx_v[i] == tw.lk_iv[i], (i, m.idx_v)
            assert m.idx_q[i] == tw.lk_iq[i], (i, m.idx_q)
    neutral = np.asarray(m.neutral())
    expected = np.zeros(m.nq)
    for k in ([3] if tw.floating else []) + tw.quaternions:
        expected[k + 3] = 1.0  # identity quaternion [0, 0, 0, 1]
    assert np.array_equal(neutral, expected)
    assert np.array_equal(tw.q_pin(neutral), pin.neutral(tw.pin_model))


# --------------------------------------------------------------------------------------------------
# Kinematics and dynamics against Pinocchio
# --------------------------------------------------------------------------------------------------


@fast(60)
@given(twins(), rngs())
def test_forward_kinematics(tw: Twin, rng):
    q = tw.random_q(rng)
    note_case(tw, q=q)
    data = tw.data()
    pin.forwardKinematics(tw.pin_model, data, tw.q_pin(q))
    assert_close(lk.forward_kinematics(tw.model, q), tw.pin_world_poses(data), "forward_kinematics")


#: legkit's inverse or forward dynamics, Pinocchio's, and the input given besides q and v.
DYNAMICS = {"rnea": (lk.rnea, pin.rnea, "a"), "aba": (lk.aba, pin.aba, "tau")}


@pytest.mark.parametrize(
    "name, with_f_ext",
    [pytest.param("rnea", False, marks=pytest.mark.slow), ("rnea", True), ("aba", False), ("aba", True)],
    ids=["rnea-no_f_ext", "rnea-f_ext", "aba-no_f_ext", "aba-f_ext"],
)
@fast(60)
@given(tw=twins(), rng=rngs())
def test_dynamics(name, with_f_ext, tw: Twin, rng):
    ours, theirs, given_input = DYNAMICS[name]
    q, v, x, f = dynamics_case(tw, rng, with_f_ext, given=given_input)
    want = theirs(tw.pin_model, tw.data(), tw.q_pin(q), tw.v_pin(v), tw.v_pin(x), *pin_f_ext(tw, f))
    assert_close(ours(tw.model, q, v, x, f), tw.v_lk(want), f"{name} with f_ext" if with_f_ext else name)
    if with_f_ext:
        # Zero external forces are the same as none.
        assert_close(ours(tw.model, q, v, x, np.zeros((tw.nbodies, 6))), ours(tw.model, q, v, x), f"{name} f_ext=0")


@pytest.mark.parametrize(
    "name, legkit_matrix, pinocchio_matrix",
    [pytest.param("crba", lk.crba, pin.crba, marks=pytest.mark.slow), ("minv", lk.minv, pin.computeMinverse)],
)
@fast(60)
@given(tw=twins(), rng=rngs())
def test_mass_matrix_and_its_inverse(name, legkit_matrix, pinocchio_matrix, tw: Twin, rng):
    """The mass matrix (crba) and its inverse (minv) agree with Pinocchio's and are exactly symmetric."""
    q = tw.random_q(rng)
    note_case(tw, q=q)
    want = tw.m_lk(pin_sym(pinocchio_matrix(tw.pin_model, tw.data(), tw.q_pin(q))))
    got = legkit_matrix(tw.model, q)
    assert_close(got, want, name)
    assert np.array_equal(got, np.asarray(got).T), f"{name} must be exactly symmetric"


@fast(60)
@given(body_counts(40), st.booleans(), st.integers(0, 2**32 - 1), rngs())
def test_gravity_option(n, floating, seed, rng):
    """Model(gravity=g) agrees with pin's model.gravity = (g, 0): rnea, generalized gravity and aba."""
    g = rng.uniform(-20.0, 20.0, size=3) * (0.0 if rng.random() < 0.1 else 1.0)
    tw = build_twin(np.random.default_rng(seed), n, floating, gravity=g)
    assert np.array_equal(np.asarray(tw.model.gravity), g)
    q, v, a = state(tw, rng)
    tau = rng.uniform(-20.0, 20.0, size=tw.nv)
    note_case(tw, q=q, v=v, a=a, tau=tau)
    pm, qp = tw.pin_model, tw.q_pin(q)
    zero = np.zeros(tw.nv)
    assert_close(lk.rnea(tw.model, q, v, a), tw.v_lk(pin.rnea(pm, tw.data(), qp, tw.v_pin(v), tw.v_pin(a))), "rnea")
    assert_close(
        lk.rnea(tw.model, q, zero, zero), tw.v_lk(pin.computeGeneralizedGravity(pm, tw.data(), qp)), "gravity torque"
    )
    assert_close(lk.aba(tw.model, q, v, tau), tw.v_lk(pin.aba(pm, tw.data(), qp, tw.v_pin(v), tw.v_pin(tau))), "aba")


@fast(40)
@given(body_counts(30), st.integers(0, 2**32 - 1), st.floats(1.0, 1e3), rngs())
def test_floating_robot_far_from_the_origin_keeps_its_precision(n, seed, distance, rng):
    """M, M^-1 and q'' do not depend on where the base is; moving it far out must not cost digits.

    Regression: with the recursions about the world origin, a 0.2 kg base 3.6 m out gave
    ||minv @ crba - I|| = 1.2e-9 (numpy's inverse of the same M: 5e-14).
    """
    tw = build_twin(np.random.default_rng(seed), n, True)
    q, v, _ = state(tw, rng)
    tau = rng.uniform(-20.0, 20.0, size=tw.nv)
    far = q.copy()
    far[:3] = distance * rng.normal(size=3) / np.sqrt(3)
    note_case(tw, q=q, v=v, tau=tau)
    mass_matrix = np.asarray(lk.crba(tw.model, far))
    assert_close(np.asarray(lk.minv(tw.model, far)) @ mass_matrix, np.eye(tw.nv), "minv @ crba, far out")
    assert_close(mass_matrix, lk.crba(tw.model, q), "crba far out vs near")
    assert_close(lk.minv(tw.model, far), lk.minv(tw.model, q), "minv far out vs near")
    assert_close(lk.aba(tw.model, far, v, tau), lk.aba(tw.model, q, v, tau), "aba far out vs near")


@fast(30)
@given(twins(), rngs())
def test_with_body_replaces_one_body_and_matches_pinocchio_with_that_inertia(tw: Twin, rng):
    body = int(rng.integers(tw.nbodies))
    assume(body > 0 or tw.floating)  # pin ignores a fixed base's inertia
    assume(tw.body_in_joint[body] is not None)
    new = lk.MassProperties.solid_box(rng.uniform(0.1, 3.0), rng.uniform(0.05, 0.5, 3), center=rng.uniform(-0.2, 0.2, 3))
    copy = tw.model.with_body(body, new)
    assert copy.body(body).mass == new.mass and tw.model.body(body).mass != new.mass  # the original is untouched
    for name in ("parents", "names", "idx_q", "idx_v", "armature", "damping", "gravity"):
        assert np.array_equal(np.asarray(getattr(copy, name)), np.asarray(getattr(tw.model, name))), name
    assert all(copy.joint_type(i) == tw.model.joint_type(i) for i in range(tw.nbodies))
    # The same body replaced in pin: its joint's inertia loses the old body (in the joint frame) and gains the new.
    reference = pin.Model(tw.pin_model)
    place = tw.body_in_joint[body]
    old = tw.model.body(body)
    joint = tw.body_joint[body]
    reference.inertias[joint] = (reference.inertias[joint] - place.act(pin.Inertia(old.mass, old.com, old.inertia))
                                 + place.act(pin.Inertia(new.mass, new.com, new.inertia)))
    q, v, a = state(tw, rng)
    want = pin.rnea(reference, reference.createData(), tw.q_pin(q), tw.v_pin(v), tw.v_pin(a))
    assert_close(lk.rnea(copy, q, v, a), tw.v_lk(want), "rnea of the copy")


def test_default_gravity():
    assert lk.STANDARD_GRAVITY == 9.81  # the one Python name for the core's default (read from it)
    assert np.array_equal(np.asarray(lk.Model().gravity), np.array([0.0, 0.0, -9.81]))
    assert np.array_equal(np.asarray(lk.Model(floating_base=True, gravity=None).gravity), np.array([0.0, 0.0, -9.81]))


# --------------------------------------------------------------------------------------------------
# Pinocchio-free self-consistency
# --------------------------------------------------------------------------------------------------


@fast(60)
@given(twins(), rngs())
def test_aba_equals_crba_solve(tw: Twin, rng):
    q, v, tau, _ = dynamics_case(tw, rng, with_f_ext=False, given="tau")
    bias = lk.rnea(tw.model, q, v, np.zeros(tw.nv))
    want = np.linalg.solve(lk.crba(tw.model, q), tau - bias) if tw.nv else np.zeros(0)
    assert_close(lk.aba(tw.model, q, v, tau), want, "aba vs solve(crba, tau - rnea(q, v, 0))")


@fast(60)
@given(twins(), rngs())
def test_minv_inverts_crba(tw: Twin, rng):
    q = tw.random_q(rng)
    note_case(tw, q=q)
    assert_close(np.asarray(lk.minv(tw.model, q)) @ np.asarray(lk.crba(tw.model, q)), np.eye(tw.nv), "minv @ crba")


# --------------------------------------------------------------------------------------------------
# Centre of mass, subtree mass properties, momentum, Jacobians, energies
# --------------------------------------------------------------------------------------------------


def com_twins(max_bodies: int = 200):
    """Twins whose bodies welded to a fixed base are massless (see the module docstring)."""
    return twins(max_bodies=max_bodies, anchored_mass=False)


def total_mass(tw: Twin) -> float:
    return sum(b[0] for b in tw.bodies if b is not None)


@pytest.mark.slow
@fast(60)
@given(com_twins(), rngs())
def test_center_of_mass(tw: Twin, rng):
    assume(total_mass(tw) > 0)
    q = tw.random_q(rng)
    note_case(tw, q=q)
    want = pin.centerOfMass(tw.pin_model, tw.data(), tw.q_pin(q))
    assert_close(lk.center_of_mass(tw.model, q), want, "center_of_mass")


def brute_force_subtrees(tw: Twin, q: np.ndarray):
    """Subtree (mass, world com, world inertia about the subtree com) of every body, from pin's joint poses."""
    data = tw.data()
    pin.forwardKinematics(tw.pin_model, data, tw.q_pin(q))
    poses = tw.pin_world_poses(data)
    n = tw.nbodies
    masses, coms, inertias = np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3, 3))
    for i, b in enumerate(tw.bodies):
        if b is None:
            continue
        R, t = poses[i][:3, :3], poses[i][:3, 3]
        masses[i], coms[i], inertias[i] = b[0], R @ b[1] + t, R @ b[2] @ R.T
    members = [[i] for i in range(n)]
    for i in range(n):
        p = i
        while p > 0:
            p = tw.parents[p]
            members[p].append(i)
    m_out, c_out, i_out = np.zeros(n), np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan)
    for k in range(n):
        idx = members[k]
        mk = masses[idx].sum()
        m_out[k] = mk
        if mk == 0:
            continue
        ck = (masses[idx, None] * coms[idx]).sum(axis=0) / mk
        inertia = np.zeros((3, 3))
        for i in idx:
            d = coms[i] - ck
            inertia += inertias[i] + masses[i] * (d @ d * np.eye(3) - np.outer(d, d))
        c_out[k], i_out[k] = ck, inertia
    return m_out, c_out, i_out, data


@pytest.mark.slow
@fast(60)
@given(com_twins(), rngs())
def test_subtree_mass_properties(tw: Twin, rng):
    q = tw.random_q(rng)
    note_case(tw, q=q)
    mass, com, inertia = lk.subtree_mass_properties(tw.model, q)
    mass, com, inertia = np.asarray(mass), np.asarray(com), np.asarray(inertia)
    want_m, want_c, want_i, _ = brute_force_subtrees(tw, q)
    assert mass.shape == (tw.nbodies,) and com.shape == (tw.nbodies, 3) and inertia.shape == (tw.nbodies, 3, 3)
    assert_close(mass, want_m, "subtree mass")
    has_mass = want_m > 0  # the com of a massless subtree is undefined
    assert_close(com[has_mass], want_c[has_mass], "subtree com")
    assert_close(inertia[has_mass], want_i[has_mass], "subtree inertia about its com")

    # Pinocchio's own subtree masses / coms for the bodies that own a pin joint. (In pin 4.1, data.com[j] of
    # a subtree is expressed in joint j's LOCAL frame: map it to the world with data.oMi[j].)
    data = tw.data()
    pin.centerOfMass(tw.pin_model, data, tw.q_pin(q), True)
    for i in range(tw.nbodies):
        if tw.kinds[i] == "fixed" or not has_mass[i]:
            continue
        j = tw.body_joint[i]
        assert_close(mass[i], data.mass[j], f"subtree mass of body {i} (pin joint {j})")
        assert_close(com[i], data.oMi[j].act(data.com[j]), f"subtree com of body {i} (pin joint {j})")


@pytest.mark.slow
@pytest.mark.parametrize("rate", [False, True], ids=["momentum", "rate"])
@fast(60)
@given(tw=com_twins(), rng=rngs())
def test_centroidal_momentum(rate: bool, tw: Twin, rng):
    assume(total_mass(tw) > 0)
    q, v, a = state(tw, rng)
    note_case(tw, q=q, v=v, a=a if rate else None)
    qp, vp, ap = tw.q_pin(q), tw.v_pin(v), tw.v_pin(a)
    if rate:
        h = pin.computeCentroidalMomentumTimeVariation(tw.pin_model, tw.data(), qp, vp, ap)
        got = lk.centroidal_momentum_rate(tw.model, q, v, a)
    else:
        h = pin.computeCentroidalMomentum(tw.pin_model, tw.data(), qp, vp)
        got = lk.centroidal_momentum(tw.model, q, v)
    assert_close(got, np.concatenate([h.linear, h.angular]), "centroidal_momentum_rate" if rate else "centroidal_momentum")


@pytest.mark.slow
@fast(60)
@given(tw=com_twins(), rng=rngs())
def test_centroidal_map(tw: Twin, rng):
    assume(total_mass(tw) > 0)
    q, _, _ = state(tw, rng)
    note_case(tw, q=q)
    # eigenpy returns a one-column map (nv = 1) as a flat array.
    pin_map = np.asarray(pin.computeCentroidalMap(tw.pin_model, tw.data(), tw.q_pin(q))).reshape(6, -1)
    # Column j is the momentum of legkit's unit velocity e_j, which pin reads as v_pin(e_j).
    want = np.stack([pin_map @ tw.v_pin(e) for e in np.eye(tw.model.nv)], axis=1)
    assert_close(lk.centroidal_map(tw.model, q), want, "centroidal_map")


@fast(60)
@given(twins(), rngs())
def test_jacobian(tw: Twin, rng):
    q = tw.random_q(rng)
    body = int(rng.integers(tw.nbodies))
    point = None if rng.random() < 0.3 else rng.uniform(-0.5, 0.5, size=3)
    note_case(tw, q=q)
    note(f"body={body}, point={None if point is None else point.tolist()!r}")
    fid = tw.add_pin_frame(body, point)
    data = tw.data()
    qp = tw.q_pin(q)
    kwargs = {} if point is None else {"point": point}
    for name, rf in FRAMES.items():
        want = tw.cols_lk(pin.computeFrameJacobian(tw.pin_model, data, qp, fid, rf))
        assert_close(lk.jacobian(tw.model, q, body, frame=name, **kwargs), want, f"jacobian frame={name}")
    default = lk.jacobian(tw.model, q, body, **kwargs)
    assert np.array_equal(default, lk.jacobian(tw.model, q, body, frame="local_world_aligned", **kwargs))
    # A body may also be named.
    assert np.array_equal(default, lk.jacobian(tw.model, q, tw.model.names[body], **kwargs))


@fast(60)
@given(twins(), rngs())
def test_point_accelerations(tw: Twin, rng):
    q, v, a = state(tw, rng)
    bodies = rng.integers(tw.nbodies, size=2)
    points = rng.uniform(-0.5, 0.5, size=(2, 3))
    note_case(tw, q=q, v=v, a=a)
    note(f"bodies={bodies.tolist()}, points={points.tolist()!r}")
    data = tw.data()
    want = []
    for body, point in zip(bodies, points):
        fid = tw.add_pin_frame(int(body), point)
        data = tw.data()
        pin.forwardKinematics(tw.pin_model, data, tw.q_pin(q), tw.v_pin(v), tw.v_pin(a))
        pin.updateFramePlacements(tw.pin_model, data)
        want.append(pin.getFrameClassicalAcceleration(tw.pin_model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear)
    got = lk.point_accelerations(tw.model, q, v, a, [(int(b), p) for b, p in zip(bodies, points)])
    assert_close(got, np.array(want), "point accelerations")


@fast(60)
@given(twins(), rngs())
def test_kinetic_energy(tw: Twin, rng):
    q, v, _ = state(tw, rng)
    note_case(tw, q=q, v=v)
    # Pinocchio 4.1 adds the armature's 1/2 a v^2 for its axis-aligned joints only (none on the *Unaligned
    # ones, although its CRBA counts it on every joint); legkit counts it on every joint, 1/2 v^T M v with
    # M from its CRBA: so pin's rigid bodies' energy plus the rotors'.
    rigid = pin.Model(tw.pin_model)
    rigid.armature = np.zeros(rigid.nv)
    want = pin.computeKineticEnergy(rigid, rigid.createData(), tw.q_pin(q), tw.v_pin(v)) + 0.5 * tw.model.armature @ (v * v)
    got = lk.kinetic_energy(tw.model, q, v)
    assert np.ndim(got) == 0
    assert_close(got, want, "kinetic_energy")
    # Independent of pin: 1/2 v^T M v.
    assert_close(got, 0.5 * v @ np.asarray(lk.crba(tw.model, q)) @ v, "kinetic_energy vs 1/2 v'Mv")


@pytest.mark.slow
@fast(60)
@given(body_counts(), st.booleans(), st.integers(0, 2**32 - 1), rngs())
def test_potential_energy(n, floating, seed, rng):
    g = None if rng.random() < 0.5 else rng.uniform(-20.0, 20.0, size=3)
    tw = build_twin(np.random.default_rng(seed), n, floating, anchored_mass=False, gravity=g)
    q = tw.random_q(rng)
    note_case(tw, q=q)
    want = pin.computePotentialEnergy(tw.pin_model, tw.data(), tw.q_pin(q))
    got = lk.potential_energy(tw.model, q)
    assert np.ndim(got) == 0
    assert_close(got, want, "potential_energy")


# --------------------------------------------------------------------------------------------------
# Batches: bit-for-bit equal to per-row calls
# --------------------------------------------------------------------------------------------------


def _call(name: str, tw: Twin, args: dict):
    m = tw.model
    if name == "forward_kinematics":
        return lk.forward_kinematics(m, args["q"])
    if name == "rnea":
        return lk.rnea(m, args["q"], args["v"], args["a"])
    if name == "rnea_f_ext":
        return lk.rnea(m, args["q"], args["v"], args["a"], args["f"])
    if name == "aba":
        return lk.aba(m, args["q"], args["v"], args["tau"])
    if name == "aba_f_ext":
        return lk.aba(m, args["q"], args["v"], args["tau"], args["f"])
    if name == "rnea_derivatives":
        return lk.rnea_derivatives(m, args["q"], args["v"], args["a"], args["f"])
    if name == "aba_derivatives":
        return lk.aba_derivatives(m, args["q"], args["v"], args["tau"], args["f"])
    if name == "centroidal_derivatives":
        return lk.centroidal_derivatives(m, args["q"], args["v"], args["a"])
    if name == "center_of_mass_jacobian":
        return lk.center_of_mass_jacobian(m, args["q"])
    if name == "crba":
        return lk.crba(m, args["q"])
    if name == "minv":
        return lk.minv(m, args["q"])
    if name == "center_of_mass":
        return lk.center_of_mass(m, args["q"])
    if name == "subtree_mass_properties":
        return lk.subtree_mass_properties(m, args["q"])
    if name == "centroidal_momentum":
        return lk.centroidal_momentum(m, args["q"], args["v"])
    if name == "centroidal_momentum_rate":
        return lk.centroidal_momentum_rate(m, args["q"], args["v"], args["a"])
    if name == "jacobian":
        return lk.jacobian(m, args["q"], args["body"], point=args["point"], frame=args["frame"])
    if name == "kinetic_energy":
        return lk.kinetic_energy(m, args["q"], args["v"])
    if name == "potential_energy":
        return lk.potential_energy(m, args["q"])
    raise AssertionError(name)


BATCHED = [
    "forward_kinematics", "rnea", "rnea_f_ext", "aba", "aba_f_ext", "crba", "minv", "center_of_mass",
    "subtree_mass_properties", "centroidal_momentum", "centroidal_momentum_rate", "jacobian", "kinetic_energy",
    "potential_energy", "rnea_derivatives", "aba_derivatives", "centroidal_derivatives", "center_of_mass_jacobian",
]  # fmt: skip


def _as_tuple(x):
    return tuple(np.asarray(y) for y in x) if isinstance(x, tuple) else (np.asarray(x),)


def _batch_args(tw: Twin, rng, shape: tuple[int, ...]):
    n = int(np.prod(shape))
    q = np.array([tw.random_q(rng) for _ in range(n)]).reshape(*shape, tw.nq)
    return {
        "q": q,
        "v": rng.uniform(-3, 3, size=(*shape, tw.nv)),
        "a": rng.uniform(-3, 3, size=(*shape, tw.nv)),
        "tau": rng.uniform(-20, 20, size=(*shape, tw.nv)),
        "f": rng.uniform(-20, 20, size=(*shape, tw.nbodies, 6)),
        "body": int(rng.integers(tw.nbodies)),
        "point": rng.uniform(-0.5, 0.5, size=3),
        "frame": ["local", "world", "local_world_aligned"][int(rng.integers(3))],
    }


def _row(args: dict, idx: tuple[int, ...]):
    return {k: (v[idx] if k in ("q", "v", "a", "tau", "f") else v) for k, v in args.items()}


@pytest.mark.parametrize("batch", [5, 300])
@pytest.mark.parametrize("name", BATCHED)
def test_batch_equals_rows(name, batch):
    @examples(4 if batch == 5 else 2)
    @given(com_twins(max_bodies=40), rngs())
    def check(tw: Twin, rng):
        if name in ("center_of_mass", "centroidal_momentum", "centroidal_momentum_rate"):
            assume(total_mass(tw) > 0)
        args = _batch_args(tw, rng, (batch,))
        got = _as_tuple(_call(name, tw, args))
        rows = [_as_tuple(_call(name, tw, _row(args, (b,)))) for b in range(batch)]
        for k, out in enumerate(got):
            want = np.stack([r[k] for r in rows])
            assert out.shape == want.shape, (name, k, out.shape, want.shape)
            assert np.array_equal(out, want, equal_nan=True), f"{name}[{k}]: batch differs from per-row calls"

    check()


@fast(10)
@given(twins(max_bodies=20), rngs())
def test_broadcasting(tw: Twin, rng):
    """Leading dimensions broadcast as in NumPy; unbatched arguments are shared by every row."""
    args = _batch_args(tw, rng, (2, 3))
    v1, a1 = args["v"][1, 2], args["a"][0, 0]
    got = np.asarray(lk.rnea(tw.model, args["q"], v1, a1[None, None, :]))
    assert got.shape == (2, 3, tw.nv)
    for i in range(2):
        for j in range(3):
            assert np.array_equal(got[i, j], lk.rnea(tw.model, args["q"][i, j], v1, a1))
    # (2, 1) against (3,) broadcasts to (2, 3).
    q21 = args["q"][:, :1]
    got = np.asarray(lk.aba(tw.model, q21, args["v"][0], args["tau"][1]))
    assert got.shape == (2, 3, tw.nv)
    for i in range(2):
        for j in range(3):
            assert np.array_equal(got[i, j], lk.aba(tw.model, args["q"][i, 0], args["v"][0, j], args["tau"][1, j]))
    # f_ext batched alone.
    got = np.asarray(lk.rnea(tw.model, args["q"][0, 0], args["v"][0, 0], args["a"][0, 0], args["f"]))
    assert got.shape == (2, 3, tw.nv)
    q0, v0, a0 = args["q"][0, 0], args["v"][0, 0], args["a"][0, 0]
    assert np.array_equal(got[1, 2], lk.rnea(tw.model, q0, v0, a0, args["f"][1, 2]))
    # Batched crba / fk shapes.
    assert np.asarray(lk.crba(tw.model, args["q"])).shape == (2, 3, tw.nv, tw.nv)
    assert np.asarray(lk.forward_kinematics(tw.model, args["q"])).shape == (2, 3, tw.nbodies, 4, 4)


# --------------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------------


def _small_model(floating: bool = True):
    rng = np.random.default_rng(7)
    for seed in range(1000):
        tw = build_twin(np.random.default_rng(seed), 5, floating, anchored_mass=False)
        if tw.nv >= (8 if floating else 2):
            return tw, tw.random_q(rng), tw.random_v(rng), tw.random_v(rng)
    raise AssertionError("no suitable model")


def _mentions(message: str, names: tuple[str, ...]) -> bool:
    return any(re.search(rf"(?<![A-Za-z0-9_]){re.escape(n)}(?![A-Za-z0-9_])", message) for n in names)


def _bad_q(q):
    bad = q.copy()
    bad[3:7] = [0.0, 0.0, 0.0, 2.0]
    return bad


def _with_nan(x, i=0):
    bad = x.copy()
    bad[i] = np.nan
    return bad


_REFLECTION = np.diag([1.0, 1.0, -1.0])
_SHEAR = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
_MP = lk.MassProperties(1.0, np.zeros(3), np.eye(3) * 0.01)
_Z = [0.0, 0.0, 1.0]


def _zero_quat(q):
    bad = q.copy()
    bad[3:7] = 0.0
    return bad


def _tile(x, n):
    return np.broadcast_to(x, (n, *np.shape(x))).copy()

# (case id, callable(model, q, v, a) -> anything, accepted argument names)
BAD_CALLS = [
    ("fk q short", lambda m, q, v, a: lk.forward_kinematics(m, q[:-1]), ("q",)),
    ("rnea q short", lambda m, q, v, a: lk.rnea(m, q[:-1], v, a), ("q",)),
    ("rnea q long", lambda m, q, v, a: lk.rnea(m, np.append(q, 0.0), v, a), ("q",)),
    ("crba q short", lambda m, q, v, a: lk.crba(m, q[:-1]), ("q",)),
    ("minv q short", lambda m, q, v, a: lk.minv(m, q[:-1]), ("q",)),
    ("aba q short", lambda m, q, v, a: lk.aba(m, q[:-1], v, a), ("q",)),
    ("rnea v nan", lambda m, q, v, a: lk.rnea(m, q, _with_nan(v, 2), a), ("v",)),
    ("aba v nan", lambda m, q, v, a: lk.aba(m, q, _with_nan(v, 7), a), ("v",)),
    ("rnea a nan", lambda m, q, v, a: lk.rnea(m, q, v, _with_nan(a)), ("a",)),
    ("rnea q nan", lambda m, q, v, a: lk.rnea(m, _with_nan(q, 8), v, a), ("q",)),
    ("aba tau nan", lambda m, q, v, a: lk.aba(m, q, v, _with_nan(a, 1)), ("tau",)),
    ("rnea quat", lambda m, q, v, a: lk.rnea(m, _bad_q(q), v, a), ("q",)),
    ("aba quat", lambda m, q, v, a: lk.aba(m, _bad_q(q), v, a), ("q",)),
    ("crba quat", lambda m, q, v, a: lk.crba(m, _bad_q(q)), ("q",)),
    ("minv quat", lambda m, q, v, a: lk.minv(m, _bad_q(q)), ("q",)),
    ("fk quat", lambda m, q, v, a: lk.forward_kinematics(m, _bad_q(q)), ("q",)),
    ("fk quat zero", lambda m, q, v, a: lk.forward_kinematics(m, _zero_quat(q)), ("q",)),
    ("aba tau short", lambda m, q, v, a: lk.aba(m, q, v, a[:-1]), ("tau",)),
    ("aba tau 2d wrong", lambda m, q, v, a: lk.aba(m, q, v, np.zeros((2, len(a) + 1))), ("tau",)),
    ("rnea v short", lambda m, q, v, a: lk.rnea(m, q, v[:-1], a), ("v",)),
    ("rnea a short", lambda m, q, v, a: lk.rnea(m, q, v, a[:-1]), ("a",)),
    ("rnea f_ext rows", lambda m, q, v, a: lk.rnea(m, q, v, a, np.zeros((m.nbodies - 1, 6))), ("f_ext",)),
    ("rnea f_ext cols", lambda m, q, v, a: lk.rnea(m, q, v, a, np.zeros((m.nbodies, 3))), ("f_ext",)),
    ("rnea f_ext flat", lambda m, q, v, a: lk.rnea(m, q, v, a, np.zeros(6)), ("f_ext",)),
    ("aba f_ext rows", lambda m, q, v, a: lk.aba(m, q, v, a, np.zeros((m.nbodies + 1, 6))), ("f_ext",)),
    ("rnea f_ext nan", lambda m, q, v, a: lk.rnea(m, q, v, a, np.full((m.nbodies, 6), np.nan)), ("f_ext",)),
    ("rnea batch mismatch", lambda m, q, v, a: lk.rnea(m, np.tile(q, (3, 1)), np.tile(v, (4, 1)), a), ("q", "v")),
    ("aba batch mismatch", lambda m, q, v, a: lk.aba(m, np.tile(q, (3, 1)), np.tile(v, (4, 1)), a), ("q", "v")),
    (
        "rnea f_ext batch mismatch",
        lambda m, q, v, a: lk.rnea(m, _tile(q, 3), v, a, _tile(np.zeros((m.nbodies, 6)), 4)),
        ("q", "f_ext"),
    ),
    ("rnea q string", lambda m, q, v, a: lk.rnea(m, "abc", v, a), ("q",)),
    ("jacobian body range", lambda m, q, v, a: lk.jacobian(m, q, m.nbodies), ("body",)),
    ("jacobian body name", lambda m, q, v, a: lk.jacobian(m, q, "no_such_body"), ("body",)),
    ("jacobian frame", lambda m, q, v, a: lk.jacobian(m, q, 1, frame="global"), ("frame",)),
    ("jacobian point", lambda m, q, v, a: lk.jacobian(m, q, 1, point=np.zeros(2)), ("point",)),
    ("jacobian q quat", lambda m, q, v, a: lk.jacobian(m, _bad_q(q), 1), ("q",)),
    ("center_of_mass q short", lambda m, q, v, a: lk.center_of_mass(m, q[:-1]), ("q",)),
    ("subtree q quat", lambda m, q, v, a: lk.subtree_mass_properties(m, _bad_q(q)), ("q",)),
    ("momentum v nan", lambda m, q, v, a: lk.centroidal_momentum(m, q, _with_nan(v)), ("v",)),
    ("momentum rate a short", lambda m, q, v, a: lk.centroidal_momentum_rate(m, q, v, a[:-1]), ("a",)),
    ("kinetic v nan", lambda m, q, v, a: lk.kinetic_energy(m, q, _with_nan(v)), ("v",)),
    ("potential q short", lambda m, q, v, a: lk.potential_energy(m, q[:-1]), ("q",)),
    ("point accelerations a short", lambda m, q, v, a: lk.point_accelerations(m, q, v, a[:-1], [(1, np.zeros(3))]), ("a",)),
    ("point accelerations body", lambda m, q, v, a: lk.point_accelerations(m, q, v, a, [(m.nbodies, np.zeros(3))]), ("body",)),
    ("rnea_derivatives q quat", lambda m, q, v, a: lk.rnea_derivatives(m, _bad_q(q), v, a), ("q",)),
    ("rnea_derivatives a short", lambda m, q, v, a: lk.rnea_derivatives(m, q, v, a[:-1]), ("a",)),
    ("rnea_derivatives f_ext rows", lambda m, q, v, a: lk.rnea_derivatives(m, q, v, a, np.zeros((m.nbodies - 1, 6))), ("f_ext",)),
    ("aba_derivatives v nan", lambda m, q, v, a: lk.aba_derivatives(m, q, _with_nan(v, 3), a), ("v",)),
    ("aba_derivatives tau short", lambda m, q, v, a: lk.aba_derivatives(m, q, v, a[:-1]), ("tau",)),
    ("aba_derivatives batch mismatch", lambda m, q, v, a: lk.aba_derivatives(m, _tile(q, 3), _tile(v, 4), a), ("q", "v")),
    ("centroidal_derivatives q quat", lambda m, q, v, a: lk.centroidal_derivatives(m, _bad_q(q), v, a), ("q",)),
    ("centroidal_derivatives v nan", lambda m, q, v, a: lk.centroidal_derivatives(m, q, _with_nan(v, 3), a), ("v",)),
    ("centroidal_derivatives a short", lambda m, q, v, a: lk.centroidal_derivatives(m, q, v, a[:-1]), ("a",)),
    ("centroidal_derivatives a string", lambda m, q, v, a: lk.centroidal_derivatives(m, q, v, "abc"), ("a",)),
    ("centroidal_derivatives batch mismatch", lambda m, q, v, a: lk.centroidal_derivatives(m, _tile(q, 3), v, _tile(a, 4)), ("q", "a")),
    ("center_of_mass_jacobian q short", lambda m, q, v, a: lk.center_of_mass_jacobian(m, q[:-1]), ("q",)),
    ("center_of_mass_jacobian q quat", lambda m, q, v, a: lk.center_of_mass_jacobian(m, _bad_q(q)), ("q",)),
]


@pytest.mark.parametrize("case, call, names", BAD_CALLS, ids=[c[0] for c in BAD_CALLS])
def test_bad_call_raises(case, call, names):
    tw, q, v, a = _small_model()
    with pytest.raises((ValueError, TypeError, IndexError)) as info:
        call(tw.model, q, v, a)
    assert _mentions(str(info.value), names), f"{case}: message {str(info.value)!r} does not name {names}"
    # The model and the interpreter are fine afterwards.
    want = pin.rnea(tw.pin_model, tw.data(), tw.q_pin(q), tw.v_pin(v), tw.v_pin(a))
    assert_close(lk.rnea(tw.model, q, v, a), tw.v_lk(want), "rnea after a bad call")


# (case id, callable(model) -> anything, accepted argument names)
BAD_BUILDS = [
    ("revolute zero axis", lambda m: m.add_revolute(0, np.zeros(3), np.eye(4), _MP, "x"), ("axis",)),
    ("prismatic zero axis", lambda m: m.add_prismatic(0, [0.0, 0.0, 0.0], np.eye(4), _MP, "x"), ("axis",)),
    ("helical zero axis", lambda m: m.add_helical(0, np.zeros(3), 0.1, np.eye(4), _MP, "x"), ("axis",)),
    ("helical nan pitch", lambda m: m.add_helical(0, _Z, np.nan, np.eye(4), _MP, "x"), ("pitch",)),
    ("revolute nan axis", lambda m: m.add_revolute(0, [np.nan, 0.0, 1.0], np.eye(4), _MP, "x"), ("axis",)),
    ("revolute axis shape", lambda m: m.add_revolute(0, [0.0, 1.0], np.eye(4), _MP, "x"), ("axis",)),
    ("revolute unknown parent", lambda m: m.add_revolute(99, [0.0, 0.0, 1.0], np.eye(4), _MP, "x"), ("parent", "body")),
    ("fixed unknown parent", lambda m: m.add_fixed(m.nbodies, np.eye(4), _MP, "x"), ("parent", "body")),
    ("prismatic negative parent", lambda m: m.add_prismatic(-1, _Z, np.eye(4), _MP, "x"), ("parent", "body")),
    ("revolute unknown parent name", lambda m: m.add_revolute("nope", _Z, np.eye(4), _MP, "x"), ("parent", "body")),
    ("placement reflection 4x4", lambda m: m.add_revolute(0, _Z, _homog(_REFLECTION), _MP, "x"), ("placement",)),
    ("placement reflection tuple", lambda m: m.add_fixed(0, (_REFLECTION, np.zeros(3)), _MP, "x"), ("placement",)),
    ("placement shear", lambda m: m.add_prismatic(0, [1.0, 0.0, 0.0], (_SHEAR, np.zeros(3)), _MP, "x"), ("placement",)),
    ("placement scaled", lambda m: m.add_revolute(0, _Z, (2.0 * np.eye(3), np.zeros(3)), _MP, "x"), ("placement",)),
    ("placement bottom row", lambda m: m.add_revolute(0, [1.0, 0.0, 0.0], _bad_bottom(), _MP, "x"), ("placement",)),
    ("placement shape", lambda m: m.add_revolute(0, [1.0, 0.0, 0.0], np.eye(3), _MP, "x"), ("placement",)),
    ("placement nan", lambda m: m.add_fixed(0, (np.eye(3), [0.0, np.nan, 0.0]), _MP, "x"), ("placement",)),
    ("duplicate name", lambda m: m.add_revolute(0, [0.0, 0.0, 1.0], np.eye(4), _MP, "b1"), ("name",)),
    ("duplicate base name", lambda m: m.add_fixed(0, np.eye(4), _MP, "base"), ("name",)),
]


def _homog(R, t=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def _bad_bottom():
    T = np.eye(4)
    T[3, 0] = 0.5
    return T


@pytest.mark.parametrize("case, build, names", BAD_BUILDS, ids=[c[0] for c in BAD_BUILDS])
def test_bad_model_building_raises(case, build, names):
    tw, q, v, a = _small_model()
    m = tw.model
    nb, nq, nv, names_before = m.nbodies, m.nq, m.nv, list(m.names)
    with pytest.raises((ValueError, TypeError, IndexError)) as info:
        build(m)
    assert _mentions(str(info.value), names), f"{case}: message {str(info.value)!r} does not name {names}"
    # A rejected add leaves the model untouched and usable.
    assert (m.nbodies, m.nq, m.nv, list(m.names)) == (nb, nq, nv, names_before)
    want = pin.rnea(tw.pin_model, tw.data(), tw.q_pin(q), tw.v_pin(v), tw.v_pin(a))
    assert_close(lk.rnea(m, q, v, a), tw.v_lk(want), "rnea after a rejected add")
    # And a valid add still works.
    i = m.add_revolute(1, [0.0, 1.0, 0.0], np.eye(4), _MP, "fresh")
    assert i == nb and m.nbodies == nb + 1 and m.nv == nv + 1
