"""Mirror periodicity over half a cycle: the sagittal mirror of the gait robots, and half-cycle transcriptions
whose unrolled trajectories are the whole cycle's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import legkit as lk
from legkit.gaits import AMBLE_QUADRUPED
from legkit.optimize import MinMaxStability, MultiphaseProblem
from legkit.optimize.gaits import amble_problem, amble_reference, guess_from_reference, walk_problem, walk_reference
from legkit.optimize.mirror import REFLECTION, Mirror, sagittal_mirror, side_mirror
from legkit.optimize.solver import solve
from legkit.robots.biped import build_biped
from legkit.robots.motors import BIPED_MOTOR, QUADRUPED_MOTOR
from legkit.robots.quadruped import DIAGONAL_PAIRS, build_quadruped

SIDES = {"biped": {"l": "r"}, "quadruped": {"lf": "rf", "lh": "rh"}}


def robot(name: str):
    return build_biped() if name == "biped" else build_quadruped(AMBLE_QUADRUPED)


def origins(model: lk.Model, q: np.ndarray) -> np.ndarray:
    """(nbodies, 3): every body frame's origin in the world."""
    return np.asarray(lk.forward_kinematics(model, q))[:, :3, 3]


def image(model: lk.Model, sides: dict[str, str]) -> list[int]:
    """Each body's mirror body, by swapping its side prefix."""
    pairs = {**sides, **{right: left for left, right in sides.items()}}

    def mirrored(name: str) -> str:
        side, _, rest = name.partition("_")
        return f"{pairs[side]}_{rest}" if rest and side in pairs else name

    return [model.names.index(mirrored(name)) for name in model.names]


@pytest.mark.parametrize("name", SIDES)
def test_side_mirror_is_an_involution_and_mirrors_the_robot(name):
    model = robot(name).model
    mirror = side_mirror(model, SIDES[name])
    rng = np.random.default_rng(3)
    q = model.neutral()
    q[7:] = rng.uniform(-0.5, 0.5, model.nq - 7)
    q[:3] = rng.uniform(-1, 1, 3)
    turn = rng.normal(size=4)
    q[3:7] = turn / np.linalg.norm(turn)
    v = rng.normal(size=model.nv)
    np.testing.assert_array_equal(mirror.q(mirror.q(q)), q)
    np.testing.assert_array_equal(mirror.v(mirror.v(v)), v)
    # Every body's origin lands on its mirror body's mirrored origin (an independent check: origins, not the
    # COMs `sagittal_mirror` matched).
    np.testing.assert_allclose(origins(model, mirror.q(q))[image(model, SIDES[name])], origins(model, q) @ REFLECTION, atol=1e-12)
    # Velocities: the mirrored motion's COM velocity is the mirrored COM velocity.
    dt = 1e-6
    com = lk.center_of_mass(model, lk.integrate(model, q, v, dt))
    com_mirror = lk.center_of_mass(model, lk.integrate(model, mirror.q(q), mirror.v(v), dt))
    np.testing.assert_allclose((com_mirror - lk.center_of_mass(model, mirror.q(q))) / dt,
                               (com - lk.center_of_mass(model, q)) / dt @ REFLECTION, atol=1e-6)


def test_an_asymmetric_pairing_or_model_is_refused():
    model = build_biped().model
    with pytest.raises(ValueError, match="bodies"):
        sagittal_mirror(model, {"l_thigh": "r_shank"})
    with pytest.raises(ValueError, match="bodies"):
        sagittal_mirror(model, {"l_thigh": "nope"})
    lopsided = model.with_body("l_foot", lk.MassProperties(2.0, [0.05, 0.02, -0.03], np.eye(3) * 0.01))
    with pytest.raises(ValueError, match="mirror"):
        side_mirror(lopsided, {"l": "r"})


def violation(problem: MultiphaseProblem, x: np.ndarray) -> np.ndarray:
    """Every constraint row's distance outside its bounds."""
    g = problem.constraints(x)
    lower = np.concatenate([b.lower for b in problem.blocks])
    upper = np.concatenate([b.upper for b in problem.blocks])
    return np.maximum(lower - g, 0.0) + np.maximum(g - upper, 0.0)


def gait_problems(name: str) -> tuple[MultiphaseProblem, MultiphaseProblem, object]:
    """(half-cycle problem, full-cycle problem, reference) of the biped walk or the amble."""
    if name == "biped":
        biped = build_biped()
        mesh = (1, 4)  # coarser than the default: small and quick
        return (walk_problem(biped, 0.5, BIPED_MOTOR, mesh, mirror=True), walk_problem(biped, 0.5, BIPED_MOTOR, mesh),
                walk_reference(biped, 0.5, mesh))
    quadruped = build_quadruped(AMBLE_QUADRUPED)
    objectives = [MinMaxStability(2.0, DIAGONAL_PAIRS)]
    return (amble_problem(quadruped, objectives, 0.67, 1.25, 2, QUADRUPED_MOTOR, mirror=True),
            amble_problem(quadruped, objectives, 0.67, 1.25, 2, QUADRUPED_MOTOR), amble_reference(quadruped, 0.67, 1.25, 2))


@pytest.mark.parametrize("name", SIDES)
def test_a_half_cycle_unrolled_violates_the_full_cycle_exactly_twice_as_much(name):
    # The hand-built reference is not a solution: its half cycle violates the dynamics. Unrolled, the whole
    # cycle must violate the full problem's constraints by the same rows twice (the mirrored half the same as
    # the half, the middle and the wrap-around boundaries as the half's wrap-around), so the sum of squares
    # doubles and the largest stays.
    half, full, reference = gait_problems(name)
    assert [set(p.contacts) for p in half.cycle_phases()] == [set(p.contacts) for p in full.phases]
    x_half = half.pack(guess_from_reference(half, reference))
    unrolled = half.unroll(half.unpack(x_half))
    whole = half.full_cycle()
    assert whole.n == 2 * half.n - 1 and [set(p.contacts) for p in whole.phases] == [set(p.contacts) for p in full.phases]
    x_full = whole.pack(unrolled)
    v_half, v_full = violation(half, x_half), violation(whole, x_full)
    assert v_half.max() > 1.0  # a test with something to double
    np.testing.assert_allclose(np.sum(v_full**2), 2.0 * np.sum(v_half**2), rtol=1e-10)
    np.testing.assert_allclose(v_full.max(), v_half.max(), rtol=1e-12)
    # The mirror image starts where the half cycle ends, one half period and half a stride on.
    assert np.isclose(unrolled.t[len(half.phases)][0], unrolled.t[len(half.phases) - 1][-1])
    np.testing.assert_allclose(unrolled.q[len(half.phases)][0, 0] - unrolled.q[0][0, 0], half.speed * np.sum(x_half[half.duration_index]))


def test_a_half_cycle_is_sampled_and_tracked_as_its_whole_cycle():
    # periodic_samples (which replay and the tracking MPC sample the plan with) of a mirrored half cycle: the second
    # half of the cycle is the first half's mirror image, moved on by half the stride, not the first half repeated.
    from legkit.optimize.replay import periodic_samples
    from legkit.optimize.tracking import TrackingModel

    half, _, reference = gait_problems("quadruped")
    trajectory = half.unpack(half.pack(guess_from_reference(half, reference)))
    period = 2.0 * float(np.sum(trajectory.durations))
    t = np.linspace(0.0, 0.5 * period, 7, endpoint=False)
    q, v, _ = periodic_samples(half, trajectory, np.concatenate([t, t + 0.5 * period]))
    first, second = q[: len(t)], q[len(t) :]
    expected = half.mirror.q(first)
    expected[:, half.travel_index] += half.speed * 0.5 * period
    np.testing.assert_allclose(second[:, 7:], expected[:, 7:], atol=1e-12)  # the joints: the other side's
    np.testing.assert_allclose(second[:, :3], expected[:, :3], atol=1e-12)
    assert np.abs(second[:, 7:] - first[:, 7:]).max() > 0.1  # the second half is not the first repeated
    np.testing.assert_allclose(v[len(t) :], half.mirror.v(v[: len(t)]), atol=1e-12)
    model = TrackingModel.build(half, trajectory, 0.0125)  # before: StopIteration (no foot swings first in a half cycle)
    assert len(model.A) == 100 and len(model.problem.phases) == 4


def test_a_solved_half_cycle_unrolled_meets_the_whole_cycles_constraints():
    # Five IPOPT iterations on the half walk's constraints (4e-8 left), stopped short of convergence (its quaternion norm
    # drifts off 1 within the defects' error): the whole cycle, unrolled, violates no row more than the half
    # did. Converged to roundoff (about 4e-13 after 6 iterations), the comparison would test nothing.
    half, _, reference = gait_problems("biped")
    result = solve(half.nlp("legkit", objective=False), half.gauged(half.pack(guess_from_reference(half, reference))), tol=1e-6, max_iter=5)
    whole = half.full_cycle()
    x_full = whole.pack(half.unroll(half.unpack(result.x)))
    worst_half = violation(half, result.x).max()
    assert 1e-10 < worst_half < 1e-3
    assert violation(whole, x_full).max() <= 1.0001 * worst_half


def test_a_wrong_mirror_breaks_the_identity():
    half, _, reference = gait_problems("biped")
    mirror = half.mirror
    assert mirror is not None
    q_sign, v_sign = mirror.q_sign.copy(), mirror.v_sign.copy()
    q_sign[9], v_sign[8] = -q_sign[9], -v_sign[8]  # one hip roll's sign flipped
    bad = dataclasses.replace(half, mirror=dataclasses.replace(mirror, q_sign=q_sign, v_sign=v_sign))
    x = bad.pack(guess_from_reference(bad, reference))
    whole = bad.full_cycle()
    ratio = np.sum(violation(whole, whole.pack(bad.unroll(bad.unpack(x))))**2) / np.sum(violation(bad, x)**2)
    assert ratio > 2.1


def test_bad_mirror_definitions_fail_clearly():
    half, _, _ = gait_problems("biped")
    with pytest.raises(ValueError, match="periodic"):
        dataclasses.replace(half, periodic=False, speed=0.0, initial=(half.model.neutral(), np.zeros(half.model.nv)))
    unpaired = Mirror(half.mirror.q_order, half.mirror.q_sign, half.mirror.v_order, half.mirror.v_sign, {"l": "r"})
    with pytest.raises(ValueError, match="mirror.feet"):
        dataclasses.replace(half, mirror=unpaired)
    with pytest.raises(TypeError, match="mirror"):
        dataclasses.replace(half, mirror="sagittal")
    # Double support alone: its mirror has the same feet, so the wrap-around would change no contact.
    with pytest.raises(ValueError, match="inconsistent contact sequence"):
        dataclasses.replace(half, phases=[half.phases[0]])
