"""Differential tests: legkit.optimize.symbolic (casadi's mirror of the kernels, for exact Hessians) against
legkit's own kernels, function by function and for a whole transcription."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import legkit as lk
from legkit.optimize import MinMaxStability, MultiphaseProblem, Phase, effort, pointwise
from legkit.optimize.mirror import side_mirror
from legkit.optimize.symbolic import SymbolicModel
from legkit.robots.quadruped import DIAGONAL_PAIRS, LEGS, build_quadruped


def random_state(model: lk.Model, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = rng.normal(size=model.nq)
    if model.floating_base:
        q[3:7] /= np.linalg.norm(q[3:7])
    return q, rng.normal(size=model.nv), rng.normal(size=model.nv)


def slider_arm() -> lk.Model:
    """Fixed base, a prismatic joint, a revolute joint and a fixed body with an off-axis COM."""
    model = lk.Model(floating_base=False)
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    slider = model.add_prismatic(0, [0.0, 0.0, 1.0], None, lk.MassProperties.solid_box(1.0, [0.1, 0.2, 0.3], center=[0.01, 0.0, 0.02]), "slider")
    arm = model.add_revolute(slider, [0.0, 1.0, 0.0], (rotation, [0.1, 0.0, 0.0]),
                             lk.MassProperties.solid_box(0.5, [0.3, 0.05, 0.05], center=[0.15, 0.0, 0.0]), "arm")
    model.add_fixed(arm, (np.eye(3), [0.3, 0.0, 0.0]), lk.MassProperties.point(0.2, [0.0, 0.01, 0.0]), "tip")
    return model


@pytest.mark.slow
@pytest.mark.parametrize("build", [lambda: build_quadruped().model, slider_arm])
def test_symbolic_kernels_match_legkit(build):
    model = build()
    symbolic = SymbolicModel(model)
    rng = np.random.default_rng(7)
    q_s, v_s, a_s = ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nv), ca.SX.sym("a", model.nv)
    body = model.nbodies - 1
    feet = [(body, np.array([0.01, -0.02, -0.1])), (body - 1 if model.floating_base else body, np.array([0.0, 0.03, 0.05]))]
    forces_s = ca.SX.sym("f", 3 * len(feet))
    functions = {
        "rnea": ca.Function("rnea", [q_s, v_s, a_s, forces_s], [symbolic.rnea(q_s, v_s, a_s, symbolic.foot_wrenches(q_s, feet, forces_s))]),
        "points": ca.Function("points", [q_s], [symbolic.points(q_s, feet)]),
        "com": ca.Function("com", [q_s], [symbolic.center_of_mass(q_s)]),
        "momentum": ca.Function("momentum", [q_s, v_s], [symbolic.centroidal_momentum(q_s, v_s)]),
        "mass": ca.Function("mass", [q_s], [symbolic.mass_matrix(q_s)]),
        "impact": ca.Function("impact", [q_s, v_s], [symbolic.impact(q_s, v_s, feet[:1])]),
    }
    for _ in range(5):
        q, v, a = random_state(model, rng)
        forces = rng.normal(size=3 * len(feet))
        poses = np.asarray(lk.forward_kinematics(model, q))
        f_ext = np.zeros((model.nbodies, 6))
        for c, (b, point) in enumerate(feet):
            local = poses[b, :3, :3].T @ forces[3 * c : 3 * c + 3]
            f_ext[b, :3] += local
            f_ext[b, 3:] += np.cross(point, local)
        np.testing.assert_allclose(np.asarray(functions["rnea"](q, v, a, forces)).ravel(), lk.rnea(model, q, v, a, f_ext), atol=1e-12)
        points = np.concatenate([poses[b, :3, :3] @ p + poses[b, :3, 3] for b, p in feet])
        np.testing.assert_allclose(np.asarray(functions["points"](q)).ravel(), points, atol=1e-14)
        np.testing.assert_allclose(np.asarray(functions["com"](q)).ravel(), lk.center_of_mass(model, q), atol=1e-14)
        np.testing.assert_allclose(np.asarray(functions["momentum"](q, v)).ravel(), lk.centroidal_momentum(model, q, v), atol=1e-13)
        np.testing.assert_allclose(np.asarray(functions["mass"](q)), lk.crba(model, q), atol=1e-13)
        v_plus, _ = lk.impact(model, q, v, feet[:1])
        np.testing.assert_allclose(np.asarray(functions["impact"](q, v)).ravel(), v_plus, atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("mirrored", [False, True], ids=["three_phases", "mirrored_half_cycle"])
def test_symbolic_transcription_matches_the_legkit_one(mirrored):
    # Every row of the symbolic NLP equals legkit's evaluation, its exact Jacobian matches the coloured
    # central differences, and the derivatives assembled point by point match casadi's of the whole graph,
    # on a three-phase quadruped problem with the smooth S_H rows and an impact; or on
    # two phases wrapping around to their mirror image (a touchdown of the mirrored feet).
    robot = build_quadruped()
    phases = [Phase(("lf", "lh"), 1, (0.1, 0.5)), Phase(("lf", "rh"), 1, (0.1, 0.5)), Phase(("rf", "rh"), 1, (0.1, 0.5))]
    mirror = side_mirror(robot.model, {"lf": "rf", "lh": "rh"}) if mirrored else None
    problem = MultiphaseProblem(robot.model, phases[:2] if mirrored else phases, {leg: robot.feet[leg] for leg in LEGS},
                                [MinMaxStability(2.0, DIAGONAL_PAIRS), effort(weight=0.1)], speed=0.3, mirror=mirror)
    assert mirror is None or problem.impulse_index.keys() == {0, 1}
    rng = np.random.default_rng(5)
    x = rng.normal(0.0, 0.3, problem.n)
    for index in problem.point_index:
        x[index[:, 2]] = 0.2
        x[index[:, 3:7]] = [0.05, -0.03, 0.02, 1.0]
    x[problem.duration_index] = 0.25
    transcribed = problem.nlp("exact").symbolic
    symbol, f, g = transcribed.x, transcribed.f, transcribed.g
    evaluate = ca.Function("nlp", [symbol], [f, g, ca.jacobian(g, symbol)])
    f_value, g_value, jacobian = evaluate(x)
    assert float(f_value) == pytest.approx(problem.objective(x), rel=1e-12)
    # 1e-8: the impact rows carry the KKT regularisation (1e-12 x impulses of order 1e2 at this random state).
    np.testing.assert_allclose(np.asarray(g_value).ravel(), problem.constraints(x), atol=1e-8, rtol=1e-10)
    dense = np.zeros((problem.m, problem.n))
    dense[problem.jac_rows, problem.jac_cols] = problem.jacobian(x)
    exact = np.asarray(ca.DM(jacobian))
    assert np.max(np.abs(dense - exact) / np.maximum(1.0, np.abs(exact))) < 1e-6
    # The point-by-point derivatives IPOPT is given (`pointwise`, compiled pieces) equal casadi's of the whole graph.
    derivatives = pointwise.derivatives(transcribed)
    lam_f, lam_g = 0.7, rng.normal(size=problem.m)
    lagrangian = lam_f * f + ca.dot(ca.DM(lam_g), g)
    whole = ca.Function("whole", [symbol], [ca.triu(ca.hessian(lagrangian, symbol)[0])])
    np.testing.assert_allclose(np.asarray(ca.DM(derivatives["jac_g"](x, [])[1])), exact, rtol=1e-12, atol=1e-12)
    hessian = np.asarray(ca.DM(whole(x)))
    assembled = np.asarray(ca.DM(derivatives["hess_lag"](x, [], lam_f, lam_g)))
    np.testing.assert_allclose(assembled, hessian, rtol=1e-10, atol=1e-10 * np.abs(hessian).max())
