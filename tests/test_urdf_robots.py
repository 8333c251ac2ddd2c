"""Every URDF that ships with example-robot-data, loaded by legkit and by Pinocchio.

legkit must load every file Pinocchio loads (what exporters write slightly wrong loads as written, with a
`lk.UrdfWarning`), refuse what Pinocchio refuses, and agree with Pinocchio's RNEA, CRBA and ABA and their derivatives to
1e-9 (relative to max(1, max|want|)) on random states, with a fixed and with a floating base (the centroidal derivatives
with a floating base: a fixed base's root link counts in legkit's centre of mass and not in Pinocchio's).

Both number the coordinates alike (Pinocchio's depth-first walk, siblings by joint name) and name the joints alike:
legkit's q, v, a, tau and every result go to Pinocchio and back as they are, index for index. The one difference is
a continuous joint's q: legkit's is its angle, Pinocchio's (cos, sin), so q is converted joint by joint, in place.

Two robots (Romeo, Romeo LAAS small) have moving joints that carry no inertia (their mass matrices are singular), so ABA is not
defined for them: for those the test checks that M is singular instead.
"""

from __future__ import annotations

import warnings
from importlib.metadata import distribution
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import legkit as lk

RTOL = 1e-9
ROBOTS = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
FILES = sorted(ROBOTS.rglob("*.urdf"))
SINGULAR_MASS_MATRIX = {"romeo.urdf", "romeo_laas_small.urdf"}


def test_example_robot_data_is_all_there():
    assert len(FILES) == 69, f"{len(FILES)} URDFs under {ROBOTS}"


def pinocchio_model(path: Path, floating: bool) -> pin.Model | None:
    try:
        return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if floating else pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError):
        return None


def legkit_model(path: Path, floating: bool) -> lk.Model:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)
        return lk.Model.from_urdf(path, floating_base=floating)


class Twin:
    """legkit's and Pinocchio's model of one URDF: the same joint names, v and q, but that each continuous joint's
    angle in legkit's q is its (cos, sin) in Pinocchio's."""

    def __init__(self, model: lk.Model, reference: pin.Model):
        self.model, self.reference = model, reference
        assert model.joint_names == list(reference.names)[1:]
        assert model.nv == reference.nv
        self.continuous = [joint.nq == 2 and joint.nv == 1 for joint in list(reference.joints)[1:]]
        # Each joint's first q index in Pinocchio's is legkit's plus the continuous joints before it; v's are equal.
        for k, (name, joint) in enumerate(zip(model.joint_names, list(reference.joints)[1:])):
            body = model.joint_index(name)
            assert (model.idx_q[body] + sum(self.continuous[:k]), model.idx_v[body]) == (joint.idx_q, joint.idx_v), name

    def state(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A random configuration in legkit's layout, and the same in Pinocchio's."""
        q = rng.uniform(-1.0, 1.0, self.model.nq)
        if self.model.floating_base:
            quaternion = rng.normal(size=4)
            q[3:7] = quaternion / np.linalg.norm(quaternion)
        return q, self.to_pin_q(q)

    def to_pin_q(self, q: np.ndarray) -> np.ndarray:
        if not any(self.continuous):
            return q
        pieces, k = [], 0
        for joint, continuous in zip(list(self.reference.joints)[1:], self.continuous):
            width = 1 if continuous else joint.nq
            pieces.append([np.cos(q[k]), np.sin(q[k])] if continuous else q[k:k + width])
            k += width
        return np.concatenate(pieces)


def assert_close(got: np.ndarray, want: np.ndarray, what: str, rtol: float = RTOL) -> None:
    assert np.all(np.isfinite(got)), f"{what}: non-finite values"
    scale = max(1.0, float(np.abs(want).max(initial=0.0)))
    error = float(np.abs(got - want).max(initial=0.0))
    assert error <= rtol * scale, f"{what}: max error {error:.3e} > {rtol:g} * {scale:.3e}"


@pytest.mark.slow
@pytest.mark.parametrize("floating", [False, True], ids=["fixed", "floating"])
@pytest.mark.parametrize("path", FILES, ids=[str(f.relative_to(ROBOTS)) for f in FILES])
def test_legkit_loads_what_pinocchio_loads_and_matches_its_dynamics(path: Path, floating: bool):
    reference = pinocchio_model(path, floating)
    if reference is None:
        with pytest.raises(ValueError, match="urdf"):
            legkit_model(path, floating)
        return
    twin = Twin(legkit_model(path, floating), reference)
    # Both read <dynamics damping> per joint (pin's free flyer has none either).
    assert np.array_equal(twin.model.damping, np.asarray(reference.damping))
    data = reference.createData()
    rng = np.random.default_rng(len(path.name))
    for _ in range(2):
        q, q_pin = twin.state(rng)
        v, a = rng.normal(size=twin.model.nv), rng.normal(size=twin.model.nv)
        assert_close(lk.rnea(twin.model, q, v, a), pin.rnea(reference, data, q_pin, v, a), "rnea")
        mass = pin.crba(reference, data, q_pin)
        mass = np.triu(mass) + np.triu(mass, 1).T
        assert_close(lk.crba(twin.model, q), mass, "crba")
        singular = mass.size > 0 and np.linalg.eigvalsh(mass).min() <= 1e-12 * np.abs(mass).max()
        assert singular == (path.name in SINGULAR_MASS_MATRIX)
        if not singular:
            tau = rng.normal(size=twin.model.nv)
            # A solve with M loses up to its condition number's worth of digits (2e9 for iCub: Pinocchio's and
            # legkit's accelerations differ by 1e-9 of the largest there, each solving M ddq = tau - b to 1e-18 of
            # |M| |ddq|; Pinocchio's derivatives multiply by a formed M^-1, where legkit's solve leaves M X + dtau/dq
            # at 1e-19 of |M| |X|): compared at 1e-9 up to a condition number of 1e6, and in proportion beyond, and
            # each of legkit's solves checked by its residual below.
            tolerance = RTOL * max(1.0, np.linalg.cond(mass) / 1e6 if mass.size else 1.0)
            got_a = lk.aba(twin.model, q, v, tau)
            assert_close(got_a, pin.aba(reference, data, q_pin, v, tau), "aba", tolerance)
            residual = np.abs(lk.rnea(twin.model, q, v, got_a) - tau).max(initial=0.0)
            assert residual <= 1e-12 * np.abs(mass).max(initial=0.0) * np.abs(got_a).max(initial=1.0), f"aba: M ddq + b - tau = {residual:.3e}"
            # Pinocchio's derivative arrays are views of `data`: copied before the next call overwrites them.
            expected_d = [np.array(x) for x in pin.computeABADerivatives(reference, data, q_pin, v, tau)]
            expected_d[2] = np.triu(expected_d[2]) + np.triu(expected_d[2], 1).T
            got_d = lk.aba_derivatives(twin.model, q, v, tau)
            for got, want, what in zip(got_d, expected_d, ["dddq/dq", "dddq/dv", "dddq/dtau"]):
                assert_close(got, want, what, tolerance)
            # Exactly: M dddq/dq = -dtau/dq and M dddq/dv = -dtau/dv at the accelerations aba gives.
            dtau = lk.rnea_derivatives(twin.model, q, v, lk.aba(twin.model, q, v, tau))
            m = lk.crba(twin.model, q)
            for got, minus, what in zip(got_d, dtau, ["dddq/dq", "dddq/dv"]):
                residual = np.abs(m @ got + minus).max(initial=0.0)
                bound = 1e-12 * np.abs(m).max(initial=0.0) * np.abs(got).max(initial=0.0)
                assert residual <= bound, f"{what}: M X + dtau = {residual:.3e}"
        expected_d = [np.array(x) for x in pin.computeRNEADerivatives(reference, data, q_pin, v, a)]
        for got, want, what in zip(lk.rnea_derivatives(twin.model, q, v, a), expected_d, ["dtau/dq", "dtau/dv"]):
            assert_close(got, want, what)
        if floating:  # a fixed base's root link counts in legkit's COM, not in Pinocchio's (its universe's)
            expected_d = pin.computeCentroidalDynamicsDerivatives(reference, data, q_pin, v, a)
            for got, want, what in zip(lk.centroidal_derivatives(twin.model, q, v, a), expected_d, ["dh/dq", "dhdot/dq", "dhdot/dv", "dhdot/da"]):
                assert_close(got, np.array(want).reshape(6, -1), what)


def test_a_non_physical_inertia_loads_as_written_with_a_warning_and_strict_refuses_it():
    go1 = ROBOTS / "go1_description/urdf/go1.urdf"  # its base link's inertia is all 1e-6: not physical
    with pytest.warns(lk.UrdfWarning, match=r'link "base": non-physical <inertial>.*kept as written'):
        model = lk.Model.from_urdf(go1)
    assert np.allclose(model.body(0).inertia, 1e-6)
    with pytest.raises(ValueError, match=r'link "base": non-physical <inertial>.*\(strict\)'):
        lk.Model.from_urdf(go1, strict=True)


def test_zero_effort_and_velocity_read_as_no_bound_with_a_warning():
    pendulum = ROBOTS / "double_pendulum_description/urdf/double_pendulum.urdf"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = lk.Model.from_urdf(pendulum)
    assert {(w.category, str(w.message)) for w in caught if "<limit>" in str(w.message)} == {
        (lk.UrdfWarning, f'urdf: joint "{joint}": <limit> {attr}="0" read as no bound')
        for joint in ("joint1", "joint2") for attr in ("effort", "velocity")
    }
    for body in range(1, model.nbodies):
        assert model.limits(body)["effort"] == model.limits(body)["velocity"] == np.inf
    with pytest.raises(ValueError, match=r'effort="0" read as no bound \(strict\)'):
        lk.Model.from_urdf(pendulum, strict=True)


def stands_on_both_engines(
    model: lk.Model, q: np.ndarray, kp: float, kd: float, feet: set[str], legs: tuple[str, ...], rtol: float
) -> dict[str, float]:
    """Servos holding ``q`` (the base free), 2 s on a plane: the robot touches the ground with ``feet`` (on
    Rapier, maybe also bodies ending in ``legs``), its contact lift is its weight within ``rtol``, its trunk is
    level; returns the base height per engine."""
    gains = np.r_[np.zeros(6), np.ones(model.nv - 6)]
    heights = {}
    for backend in ("tree", "rapier"):
        sim = lk.Simulation(model, ground=lk.Ground.plane(0.8), backend=backend)
        sim.reset(q, None)
        sim.set_servo(kp=kp * gains, kd=kd * gains, target_q=q)
        sim.step(n=2000)
        contacts = sim.contacts()
        touching = {model.names[b] for b in contacts["body"]}
        assert feet <= touching and all(name.endswith(legs) for name in touching), (backend, touching)
        if backend == "tree":
            assert touching == feet
        lift = contacts["normal"][:, 2] * contacts["normal_force"] + contacts["tangential_force"][:, 2]
        weight = model.total_mass * -model.gravity[2]
        assert abs(lift.sum() - weight) <= rtol * weight, (backend, lift.sum(), weight)
        base = lk.forward_kinematics(model, sim.q)[0]
        assert base[2, 2] > 0.999, f"{backend}: the trunk tilts ({base[:3, 2]})"
        heights[backend] = sim.q[2]
    return heights


GO1_THIGH, GO1_CALF = 0.9, -1.8  # rad: Go1's crouch


def go1_crouched() -> tuple[lk.Model, np.ndarray]:
    """Go1 with a floating base, and its crouch 0.3 m up."""
    model = legkit_model(ROBOTS / "go1_description/urdf/go1.urdf", floating=True)
    q = model.neutral()
    for body in range(1, model.nbodies):
        for suffix, angle in (("_thigh", GO1_THIGH), ("_calf", GO1_CALF)):
            if model.names[body].endswith(suffix):
                q[model.idx_q[body]] = angle
    q[2] = 0.3
    return model, q


def test_go1_stands_on_its_own_collision_geometry():
    """Go1's URDF gives each foot a 2 cm sphere (and boxes and cylinders elsewhere): on servos holding a
    crouch it stands on the four foot spheres, carrying its weight, level, on both engines."""
    model, q = go1_crouched()
    heights = stands_on_both_engines(model, q, 60.0, 2.0, {"FL_foot", "FR_foot", "RL_foot", "RR_foot"}, ("_foot", "_calf"), 0.01)
    assert abs(heights["tree"] - heights["rapier"]) <= 3e-3, heights


def test_solo12_stands_on_the_convex_hulls_of_its_collision_meshes():
    """Solo-12's URDF collides through STL meshes (package:// names, found beside the URDF): legkit wraps each
    in its convex hull, and on servos holding a crouch the robot stands on its four feet, level, carrying
    its weight, on both engines."""
    model = legkit_model(ROBOTS / "solo_description/robots/solo12.urdf", floating=True)
    colliders = model.colliders()
    assert len(colliders) == model.nbodies and all(kind == "convex" for _, kind, _, _ in colliders)
    q = model.neutral()
    for body in range(1, model.nbodies):
        name = model.names[body]
        front = name.startswith("F")
        if name.endswith("UPPER_LEG"):
            q[model.idx_q[body]] = 0.8 if front else -0.8
        if name.endswith("LOWER_LEG"):
            q[model.idx_q[body]] = -1.6 if front else 1.6
    q[2] = 0.3
    heights = stands_on_both_engines(model, q, 5.0, 0.1, {"FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"}, ("_FOOT", "_LOWER_LEG"), 1e-3)
    assert abs(heights["tree"] - heights["rapier"]) <= 2e-3, heights


def test_go1_trots_forward_under_pd_on_both_engines():
    """An open-loop trot on joint PD servos (diagonal legs in phase at 2 Hz: thighs swing +-0.25 rad, a
    knee flexes by up to 0.5 rad while its leg swings forward): after standing 0.5 s, Go1 walks forward
    for 3 s, straight and level, and both engines agree on how far (measured: 0.73 m on each)."""
    model, q0 = go1_crouched()
    thighs = [model.idx_q[b] for b in range(1, model.nbodies) if model.names[b].endswith("_thigh")]
    calves = [model.idx_q[b] for b in range(1, model.nbodies) if model.names[b].endswith("_calf")]
    # FL and RR swing together, FR and RL half a period later (the legs named in body order).
    thigh_bodies = [b for b in range(1, model.nbodies) if model.names[b].endswith("_thigh")]
    phase = np.array([0.0 if model.names[b].startswith(("FL", "RR")) else np.pi for b in thigh_bodies])
    times = np.arange(3000) * 1e-3
    angle = 2 * np.pi * 2.0 * times[:, None] + phase
    targets = np.repeat(q0[None], times.size, axis=0)
    targets[:, thighs] = GO1_THIGH - 0.25 * np.sin(angle)
    targets[:, calves] = GO1_CALF - 0.5 * np.maximum(0.0, np.cos(angle))
    gains = np.r_[np.zeros(6), np.ones(model.nv - 6)]
    travelled = {}
    for backend in ("tree", "rapier"):
        sim = lk.Simulation(model, ground=lk.Ground.plane(0.8), backend=backend)
        sim.reset(q0, None)
        sim.set_servo(kp=40.0 * gains, kd=1.0 * gains, target_q=q0)
        sim.step(n=500)
        start = sim.q[:3].copy()
        for target in targets:
            sim.set_servo(kp=40.0 * gains, kd=1.0 * gains, target_q=target)
            sim.step()
        moved = sim.q[:3] - start
        x, y = sim.q[3:5]
        assert moved[0] > 0.5 and abs(moved[1]) < 0.1, (backend, moved)
        assert 1 - 2 * (x * x + y * y) > 0.99, (backend, sim.q[3:7])
        travelled[backend] = moved[0]
    assert abs(travelled["tree"] - travelled["rapier"]) < 0.05, travelled


SECOND_ORDER_ROBOTS = ["solo_description/robots/solo12.urdf", "go1_description/urdf/go1.urdf", "panda_description/urdf/panda.urdf"]


@pytest.mark.slow
@pytest.mark.parametrize("relative", SECOND_ORDER_ROBOTS)
def test_second_order_derivatives_are_the_slopes_of_pinocchios_first(relative: str):
    """``rnea_second_order_derivatives`` on real robots (floating legged ones, a fixed arm) against central differences
    (five-point, h = 1e-4) of Pinocchio's ``computeRNEADerivatives`` and ``crba``, q stepped on its tangent space."""
    path = ROBOTS / relative
    floating = "panda" not in relative
    reference = pinocchio_model(path, floating)
    assert reference is not None
    twin = Twin(legkit_model(path, floating), reference)
    data, nv, h = reference.createData(), twin.model.nv, 1e-4
    rng = np.random.default_rng(3)
    q, _ = twin.state(rng)
    v, a = rng.normal(size=nv), rng.normal(size=nv)

    def first(q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        q_pin = twin.to_pin_q(q)
        dq, dv = (np.array(x) for x in pin.computeRNEADerivatives(reference, data, q_pin, v, a)[:2])
        mass = pin.crba(reference, data, q_pin)
        return dq, dv, np.triu(mass) + np.triu(mass, 1).T

    def slope(at) -> np.ndarray:
        """Five-point slopes of `at(j, step)` for each coordinate j, stacked along a last axis."""
        return np.stack([(at(j, -2 * h) - 8 * at(j, -h) + 8 * at(j, h) - at(j, 2 * h)) / (12 * h) for j in range(nv)], axis=-1)

    along_q = slope(lambda j, s: np.stack(first(lk.integrate(twin.model, q, np.eye(nv)[j], s), v)))
    along_v = slope(lambda j, s: np.stack(first(q, v + s * np.eye(nv)[j])))
    dqdq, dvdv, dqdv, dadq = lk.rnea_second_order_derivatives(twin.model, q, v, a)
    for got, want, what in [(dqdq, along_q[0], "d2tau/dqdq"), (dadq, along_q[2], "d2tau/dadq"), (dvdv, along_v[1], "d2tau/dvdv"),
                            (dqdv, along_v[0], "d2tau/dqdv")]:
        assert_close(got, want, what, rtol=1e-6)


def test_talos_resolves_every_collision_mesh_pinocchio_resolves():
    """talos_full_v2.urdf names its meshes package:///example-robot-data/robots/talos_data/... (three slashes):
    with the same package_dirs, legkit reads every collision geometry Pinocchio's buildGeomFromUrdf reads, each
    of the same kind (a mesh as its convex hull), and no link falls back to the box of its inertia."""
    share = ROBOTS.parent.parent
    path = ROBOTS / "talos_data/robots/talos_full_v2.urdf"
    with warnings.catch_warnings():
        warnings.simplefilter("error", lk.UrdfWarning)
        model = lk.Model.from_urdf(path, package_dirs=[share])
    geometry = pin.buildGeomFromUrdf(pin.buildModelFromUrdf(str(path)), str(path), pin.COLLISION, package_dirs=[str(share)])
    kinds = {"BVHModelOBBRSS": "convex", "Cylinder": "cylinder", "Box": "box", "Sphere": "sphere", "Capsule": "capsule"}
    want = sorted((g.name.rsplit("_", 1)[0], kinds[type(g.geometry).__name__]) for g in geometry.geometryObjects)
    got = sorted((model.names[body], kind) for body, kind, _, _ in model.colliders())
    assert len(got) == geometry.ngeoms == 52
    assert got == want
