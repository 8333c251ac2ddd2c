"""lk.Simulation (the default tree engine) against legkit's dynamics core, statics, terrain, actuation and input checks."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples

G = lk.STANDARD_GRAVITY


def rotation(axis, angle):
    """Rodrigues rotation matrix about a unit axis."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def rod(mass, length):
    """A 4 cm square bar along the body x axis, starting at the joint."""
    return lk.MassProperties.solid_box(mass, [length, 0.04, 0.04], center=[length / 2, 0, 0])


def ten_link_tree():
    """A 10-link tree hanging from a fixed base: chain of 5 plus side branches, one prismatic joint."""
    model = lk.Model(floating_base=False, base=lk.MassProperties.solid_box(1.0, [0.1, 0.1, 0.1]))
    axes = [[0, 1, 0], [0, 1, 0.3], [0, 0, 1], [0.2, 1, 0], [0, 1, 0]]
    chain, parent = [], 0
    for k, axis in enumerate(axes):
        placement = (rotation([0, 1, 0], math.pi / 2), np.zeros(3)) if k == 0 else (rotation([1, 0.2, 0.3], 0.25), [0.25, 0, 0])
        parent = model.add_revolute(parent, axis, placement, rod(0.6 - 0.05 * k, 0.25), f"chain{k}")
        chain.append(parent)
    side = model.add_revolute(chain[1], [1, 0, 0], (rotation([0, 0, 1], 1.2), [0.25, 0, 0]), rod(0.3, 0.2), "side0")
    model.add_revolute(side, [0, 0.4, 1], (rotation([1, 0, 0], 0.3), [0.2, 0, 0]), rod(0.2, 0.15), "side1")
    slider = model.add_prismatic(chain[2], [1, 0, 0], (rotation([0, 1, -2], 1.0), [0.25, 0, 0]), rod(0.25, 0.2), "slider")
    model.add_revolute(slider, [0, 1, 0], (np.eye(3), [0.2, 0, 0]), rod(0.2, 0.2), "side2")
    model.add_revolute(chain[4], [0, 0, 1], (rotation([0, 0, 1], -0.4), [0.25, 0, 0]), rod(0.15, 0.15), "tip")
    return model


LEG_LENGTH = 0.15
FOOT_RADIUS = 0.02


def quadruped():
    """A floating 4 kg body on four hip/knee legs (axes y) with ball feet; thighs have no collider."""
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(4.0, [0.4, 0.2, 0.06]))
    shapes = {}

    def segment(m: float) -> lk.MassProperties:
        return lk.MassProperties.solid_box(m, [0.03, 0.03, LEG_LENGTH], center=[0, 0, -LEG_LENGTH / 2])

    for k, (x, y) in enumerate([(0.15, 0.08), (0.15, -0.08), (-0.15, 0.08), (-0.15, -0.08)]):
        thigh = model.add_revolute(0, [0, 1, 0], (np.eye(3), [x, y, -0.03]), segment(0.3), f"thigh{k}")
        model.add_revolute(thigh, [0, 1, 0], (np.eye(3), [0, 0, -LEG_LENGTH]), segment(0.2), f"shin{k}")
        foot = np.eye(4)
        foot[2, 3] = -LEG_LENGTH
        shapes[thigh] = None
        shapes[f"shin{k}"] = ("sphere", FOOT_RADIUS, foot)
    return model, shapes


def standing_quadruped(ground, height=0.03 + 2 * LEG_LENGTH + FOOT_RADIUS + 0.005, substeps=1, kp=40.0, kd=0.3, friction_law="coulomb"):
    model, shapes = quadruped()
    sim = lk.Simulation(model, dt=1e-3, ground=ground, shapes=shapes, substeps=substeps, friction_law=friction_law)
    q = model.neutral()
    q[2] = height
    sim.q = q
    # kd is explicit (sampled each step): keep kd dt / (shin inertia, 1.5e-3 kg m^2) well below 1.
    sim.set_servo(kp=kp, kd=kd, torque_limit=20.0, target_q=model.neutral())
    return sim


def total_contact_force(contacts):
    return (contacts["normal"] * contacts["normal_force"][:, None] + contacts["tangential_force"]).sum(axis=0)


def test_free_tree_follows_aba_rk4_within_a_milliradian():
    model = ten_link_tree()
    q0 = 0.3 * np.sin(1.7 * np.arange(model.nq))
    v0 = np.zeros(model.nv)
    qs, _ = lk.free_rollout(model, q0, v0, 1e-3, 1000, method="rk4")
    errors = []
    for substeps in (1, 8, 32):
        sim = lk.Simulation(model, dt=1e-3, substeps=substeps)
        sim.q, sim.v = q0, v0
        sim.step(n=1000)
        assert sim.time == pytest.approx(1.0)
        errors.append(np.abs(sim.q - qs[-1]).max())
    # The integrator is first order in the substep (semi-implicit Euler): the error
    # shrinks in proportion, and 32 substeps per 1 ms step bring it within 1e-3 rad after 1 s.
    assert 7 < errors[0] / errors[1] < 9 and 3.5 < errors[1] / errors[2] < 4.5
    assert errors[2] < 1e-3


@examples(40)
@given(st.integers(1, 6), st.integers(0, 2**31 - 1))
def test_first_step_from_rest_uses_the_aba_acceleration(links, seed):
    # From rest Coriolis and gyroscopic terms vanish, so the first velocity is exactly dt * aba(q, 0, tau).
    rng = np.random.default_rng(seed)
    base = lk.MassProperties.solid_box(2.0, rng.uniform(0.1, 0.4, 3), center=rng.uniform(-0.05, 0.05, 3))
    model = lk.Model(floating_base=bool(seed % 2), base=base)
    for i in range(1, links + 1):
        axis = rng.normal(size=3)
        placement = (rotation(rng.normal(size=3), rng.uniform(-3, 3)), rng.uniform(-0.3, 0.3, 3))
        body = lk.MassProperties.solid_box(
            rng.uniform(0.2, 2), rng.uniform(0.05, 0.4, 3), center=rng.uniform(-0.1, 0.1, 3), rotation=rotation(rng.normal(size=3), 1.0)
        )
        adder = model.add_prismatic if rng.uniform() < 0.2 else model.add_revolute
        adder(int(rng.integers(0, i)), axis, placement, body)
    q = model.neutral()
    q[model.nq - links :] = rng.uniform(-2, 2, links)
    if model.floating_base:
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
    tau = rng.uniform(-3, 3, model.nv)
    sim = lk.Simulation(model, dt=1e-4)
    sim.q = q
    sim.step(tau)
    expected = lk.aba(model, q, np.zeros(model.nv), tau)
    np.testing.assert_allclose(sim.v / 1e-4, expected, rtol=1e-6, atol=1e-6 * np.abs(expected).max())


@pytest.mark.parametrize("backend", ["tree", "rapier"])
def test_model_armature_adds_to_the_mass_matrix_diagonal_joint_by_joint(backend):
    # From rest the first step's velocity is dt * (M + diag(a))^-1 (tau - g); the armature a is the model's,
    # one value per joint, so every dynamics function and both backends must agree with it.
    model = lk.Model()
    parent = 0
    for i in range(3):
        body = lk.MassProperties.solid_box(0.3, [0.2, 0.04, 0.04], center=[0.1, 0.0, 0.0])
        parent = model.add_revolute(parent, [0.0, 1.0, 0.0] if i % 2 == 0 else [0.0, 0.0, 1.0], (np.eye(3), [0.2 * (i > 0), 0.0, 0.0]), body)
    q, tau, armature = np.array([0.4, -0.3, 0.7]), np.array([0.2, -0.1, 0.05]), np.array([0.01, 0.0, 0.03])
    rigid = lk.crba(model, q)
    bias = lk.rnea(model, q, np.zeros(3), np.zeros(3))
    model.armature = armature
    expected = np.linalg.solve(rigid + np.diag(armature), tau - bias)
    np.testing.assert_allclose(lk.crba(model, q), rigid + np.diag(armature), rtol=0, atol=1e-15)
    np.testing.assert_allclose(lk.aba(model, q, np.zeros(3), tau), expected, rtol=1e-12)
    np.testing.assert_allclose(lk.rnea(model, q, np.zeros(3), expected), tau, rtol=1e-12)
    np.testing.assert_allclose(lk.minv(model, q), np.linalg.inv(rigid + np.diag(armature)), rtol=1e-10)
    assert np.abs(expected - np.linalg.solve(rigid, tau - bias)).max() > 1e-3
    sim = lk.Simulation(model, dt=1e-4, backend=backend)
    sim.q = q
    sim.step(tau)
    np.testing.assert_allclose(sim.v / 1e-4, expected, rtol=1e-6, atol=1e-9)


def test_armature_and_damping_are_set_whole_and_checked():
    model, _ = quadruped()  # floating: the base's six coordinates have neither
    model.armature = 0.02
    assert np.array_equal(model.armature, np.r_[np.zeros(6), np.full(model.nv - 6, 0.02)])
    with pytest.raises(ValueError, match="read-only"):
        model.damping[7] = 1.0
    for bad in (-1.0, np.nan, np.ones(model.nv), np.zeros(model.nv + 1)):
        for name in ("armature", "damping"):
            with pytest.raises(ValueError, match=name):
                setattr(model, name, bad)
    assert np.array_equal(model.armature, np.r_[np.zeros(6), np.full(model.nv - 6, 0.02)]) and not model.damping.any()


def test_identical_inputs_give_bit_identical_trajectories():
    terrain = lk.Ground.heightfield(0.02 * np.sin(np.arange(21)[:, None] * 0.7 + np.arange(15)[None, :] * 0.4), 0.1, 0.8)

    def run():
        sim = standing_quadruped(terrain, height=0.5, substeps=2)
        tau = np.where(np.arange(sim.v.size) < 6, 0.0, 0.4 * np.sin(np.arange(sim.v.size)))
        trajectory = []
        for _ in range(20):
            sim.step(tau, n=25)
            trajectory.append(np.concatenate([sim.q, sim.v, sim.applied_tau]))
        return np.array(trajectory), sim.contacts(), sim.body_poses()

    (a, contacts_a, poses_a), (b, contacts_b, poses_b) = run(), run()
    assert np.array_equal(a, b)
    assert np.array_equal(poses_a, poses_b)
    assert contacts_a.keys() == contacts_b.keys() and all(np.array_equal(contacts_a[k], contacts_b[k]) for k in contacts_a)


def test_reset_is_a_fresh_start():
    sim = standing_quadruped(lk.Ground.plane(0.8))
    q0, v0 = sim.q, sim.v
    sim.step(n=300)
    expected = sim.q
    sim.step(n=77)
    sim.reset(q0, v0)
    assert sim.time == 0.0
    sim.step(n=300)
    assert np.array_equal(sim.q, expected)


def test_standing_quadruped_contact_forces_carry_its_weight():
    sim = standing_quadruped(lk.Ground.plane(0.8))
    sim.step(n=2000)
    contacts = sim.contacts()
    weight = sim_weight = 4.0 + 4 * (0.3 + 0.2)
    assert len(contacts["body"]) == 4 and set(contacts["other"]) == {-1}
    force = total_contact_force(contacts)
    assert abs(contacts["normal_force"].sum() - weight * G) < 0.01 * sim_weight * G
    assert np.abs(force[:2]).max() < 0.01 * weight * G
    np.testing.assert_allclose(contacts["normal"], np.tile([0, 0, 1.0], (4, 1)), atol=1e-12)
    assert np.abs(sim.v).max() < 1e-3


def test_box_at_rest_on_a_slope_is_held_by_friction():
    # A tilted plane as a heightfield: the resting box's contact forces (normal plus friction) sum to its
    # weight, straight up, with the normal tilted by the slope angle.
    slope = 0.2
    x = (np.arange(41) - 20) * 0.05
    heights = np.tile(slope * x[:, None], (1, 41))
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(2.0, [0.2, 0.2, 0.1]))
    sim = lk.Simulation(model, ground=lk.Ground.heightfield(heights, 0.05, friction=0.9))
    angle = math.atan(slope)
    half = math.sin(angle / 2)
    sim.q = [0, 0, 0.06, 0, -half, 0, math.cos(angle / 2)]
    sim.step(n=1500)
    contacts = sim.contacts()
    force = total_contact_force(contacts)
    np.testing.assert_allclose(force, [0, 0, 2.0 * G], atol=0.01 * 2.0 * G)
    # The points carrying load sit on the slope, normal to it (others are unloaded speculative contacts).
    loaded = contacts["normal_force"] > 1e-6
    normal = np.array([-math.sin(angle), 0, math.cos(angle)])
    assert loaded.sum() >= 3
    np.testing.assert_allclose(contacts["normal"][loaded], np.tile(normal, (loaded.sum(), 1)), atol=1e-6)
    assert np.abs(contacts["tangential_force"] @ normal).max() < 1e-9


def terrain_distance(points_xz, xs, hs):
    """Distance from points (k, 2) in the xz plane to the polyline (xs, hs), brute force over segments."""
    a = np.stack([xs[:-1], hs[:-1]], axis=1)
    b = np.stack([xs[1:], hs[1:]], axis=1)
    d = b - a
    t = np.clip(((points_xz[:, None, :] - a) * d).sum(-1) / (d * d).sum(-1), 0, 1)
    nearest = a + t[..., None] * d
    return np.linalg.norm(points_xz[:, None, :] - nearest, axis=-1).min(axis=1)


def test_quadruped_dropped_on_a_heightfield_settles_without_sinking_in():
    # Ridges along y (heights depend on x only), so the terrain is exactly a polyline in the xz plane.
    xs = (np.arange(61) - 30) * 0.025
    hs = 0.015 * np.sin(2 * math.pi * xs / 0.6) + 0.01 * np.cos(2 * math.pi * xs / 0.25)
    ground = lk.Ground.heightfield(np.tile(hs[:, None], (1, 31)), 0.025, friction=0.9)
    # Dropped 2-4.5 cm (standing height 0.35 m over terrain within +-2.5 cm). From higher up the landing is
    # chaotic: the front feet land on ridges of slope up to 0.40 and may slide down them at mu N, pitching
    # the robot onto its back, and whether they do flips with the drop height by a centimetre in every
    # engine (dropped from 0.40-0.44 m: the cone law falls over from 0.40 and 0.41, Coulomb's from all but
    # 0.42, MuJoCo's elliptic cone from 0.39 and 0.42 with its default contacts and from none when stiff).
    # From 0.355-0.39 m all of them, and Rapier, settle on four feet.
    sim = standing_quadruped(ground, height=0.37, kp=300.0, kd=0.5)
    sim.step(n=3000)
    assert np.abs(sim.v).max() < 1e-2, "the robot should have come to rest"
    poses = sim.body_poses()
    feet = [poses[sim_index][:3, :3] @ [0, 0, -LEG_LENGTH] + poses[sim_index][:3, 3] for sim_index in (2, 4, 6, 8)]
    feet = np.array(feet)
    penetration = FOOT_RADIUS - terrain_distance(feet[:, [0, 2]], xs, hs)
    assert penetration.max() <= sim.contact_tolerance
    contacts = sim.contacts()
    assert set(contacts["body"]) == {2, 4, 6, 8}
    assert contacts["depth"].max() <= sim.contact_tolerance
    assert abs(total_contact_force(contacts)[2] - 6.0 * G) < 0.01 * 6.0 * G


@pytest.mark.parametrize("backend", ["tree", "rapier"])
def test_servo_torques_stay_within_their_limits(backend):
    model = ten_link_tree()
    sim = lk.Simulation(model, backend=backend)
    sim.q = 0.5 * np.cos(np.arange(model.nq))
    limit = np.linspace(0.5, 2.0, model.nv)
    sim.set_servo(kp=200.0, kd=3.0, torque_limit=limit, target_q=np.zeros(model.nq))
    applied = []
    for _ in range(500):
        sim.step(np.full(model.nv, 0.7))
        applied.append(sim.applied_tau)
    applied = np.array(applied)
    assert np.all(np.abs(applied) <= limit)
    assert np.any(np.isclose(np.abs(applied), limit))
    # Below the limits the servo law holds exactly: sampled at the start of the step on Rapier, at its end
    # on the tree engine, which integrates the PD terms implicitly.
    sim.set_servo(kp=2.0, kd=0.5, torque_limit=100.0, target_q=np.zeros(model.nq))
    q, v = sim.q, sim.v
    sim.step(np.full(model.nv, 0.1))
    if backend == "tree":
        q, v = sim.q, sim.v
    np.testing.assert_allclose(sim.applied_tau, 2.0 * (0 - q) + 0.5 * (0 - v) + 0.1, rtol=1e-12)


def test_body_poses_match_forward_kinematics():
    model, shapes = quadruped()
    sim = lk.Simulation(model, shapes=shapes)
    q = model.neutral()
    q[:3] = [0.3, -0.2, 0.8]
    q[3:7] = [0.1, -0.2, 0.3, 0.9] / np.linalg.norm([0.1, -0.2, 0.3, 0.9])
    q[7:] = np.linspace(-1, 1, 8)
    sim.q = q
    np.testing.assert_allclose(sim.body_poses(), lk.forward_kinematics(model, q), atol=1e-12)
    np.testing.assert_allclose(sim.q, q, atol=1e-15)


def test_bad_input_raises_and_leaves_the_state_unchanged():
    model = ten_link_tree()
    sim = lk.Simulation(model, ground=lk.Ground.plane())
    sim.q = 0.2 * np.ones(model.nq)
    sim.step(n=5)
    before = (sim.q, sim.v, sim.time, sim.applied_tau)
    bad_tau = np.zeros(model.nv)
    bad_tau[2] = np.nan
    with pytest.raises(ValueError, match="tau"):
        sim.step(bad_tau)
    with pytest.raises(ValueError, match="tau"):
        sim.step(np.zeros(3))
    with pytest.raises(ValueError, match="q"):
        sim.q = np.zeros(model.nq + 1)
    with pytest.raises(ValueError, match="v"):
        sim.v = np.full(model.nv, np.inf)
    with pytest.raises(ValueError, match="kp"):
        sim.set_servo(kp=-1.0)
    with pytest.raises(ValueError, match="kd"):
        sim.set_servo(kp=np.ones(model.nv), kd=np.ones(3))
    with pytest.raises(ValueError, match="torque_limit"):
        sim.set_servo(kp=1.0, torque_limit=-1.0)
    with pytest.raises(ValueError, match="target_q"):
        sim.set_servo(kp=1.0, target_q=np.zeros(2))
    with pytest.raises(ValueError, match="v"):
        sim.reset(np.zeros(model.nq), np.zeros(model.nv + 2))
    with pytest.raises(ValueError, match="n"):
        sim.step(n=-1)
    after = (sim.q, sim.v, sim.time, sim.applied_tau)
    assert all(np.array_equal(x, y) for x, y in zip(before, after))


def test_bad_construction_arguments_name_the_argument():
    model = ten_link_tree()
    for dt in (0.0, -1e-3, float("nan")):
        with pytest.raises(ValueError, match="dt"):
            lk.Simulation(model, dt=dt)
    with pytest.raises(ValueError, match="heights"):
        lk.Ground.heightfield(np.zeros(10), 0.1)
    with pytest.raises(ValueError, match="heights"):
        lk.Ground.heightfield(np.zeros((1, 10)), 0.1)
    with pytest.raises(ValueError, match="heights"):
        lk.Ground.heightfield(np.full((3, 3), np.nan), 0.1)
    with pytest.raises(ValueError, match="cell_size"):
        lk.Ground.heightfield(np.zeros((3, 3)), 0.0)
    with pytest.raises(ValueError, match="friction"):
        lk.Ground.plane(-0.1)
    with pytest.raises(ValueError, match="shapes"):
        lk.Simulation(model, shapes={1: ("sphere", -0.1)})
    with pytest.raises(ValueError, match="shapes"):
        lk.Simulation(model, shapes={1: ("cone", 0.1)})
    with pytest.raises(IndexError, match="shapes"):
        lk.Simulation(model, shapes={"nope": ("sphere", 0.1)})
    with pytest.raises(ValueError, match="substeps"):
        lk.Simulation(model, substeps=0)
    with pytest.raises(ValueError, match="kp"):
        # A floating base cannot be servoed.
        model_f, _ = quadruped()
        lk.Simulation(model_f).set_servo(kp=np.ones(model_f.nv))


def test_joint_damping_dissipates_and_is_absent_by_default():
    # A single pendulum: without damping its energy is conserved to integrator accuracy; with damping it decays.
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0, 1, 0], None, rod(1.0, 0.5))
    energies = []
    for damping in (0.0, 0.05):
        model.damping = damping
        sim = lk.Simulation(model, substeps=4)
        sim.q = [1.0]
        e0 = lk.kinetic_energy(model, sim.q, sim.v) + lk.potential_energy(model, sim.q)
        sim.step(n=3000)
        energies.append((lk.kinetic_energy(model, sim.q, sim.v) + lk.potential_energy(model, sim.q) - e0) / abs(e0))
    assert abs(energies[0]) < 2e-3
    assert energies[1] < -0.1


# Joint limits: stored on the Model, ignored by the dynamics, enforced by the simulation.

ROD_MASS, ROD_LENGTH = 1.0, 0.5
# Rod inertia about the joint (y axis): box about its COM plus the parallel-axis term.
ROD_INERTIA = ROD_MASS * (ROD_LENGTH**2 + 0.04**2) / 12 + ROD_MASS * (ROD_LENGTH / 2) ** 2


def inverted_pendulum(limits=None):
    """A 1 kg, 0.5 m rod standing up on a revolute joint about y; q > 0 leans it toward +x, where gravity pulls."""
    model = lk.Model(floating_base=False)
    # Body x (the rod) onto world +z.
    model.add_revolute(0, [0, 1, 0], (rotation([0, 1, 0], -math.pi / 2), np.zeros(3)), rod(ROD_MASS, ROD_LENGTH), "rod", limits=limits)
    return model


def joint_excursion(sim, steps):
    """Largest and smallest joint coordinate over `steps` single steps."""
    qs = np.empty(steps)
    for k in range(steps):
        sim.step()
        qs[k] = sim.q[0]
    return qs.max(), qs.min()


@examples(30)
@given(st.floats(0.2, 1.2), st.floats(0.3, 0.95), st.sampled_from([1.0, -1.0]), st.sampled_from([1, 2, 4]))
def test_falling_pendulum_stops_at_its_position_limit(limit, start_fraction, side, substeps):
    # Rapier's limit engages once the coordinate is past a bound, the tree engine's just before it (a
    # speculative constraint); either way semi-implicit Euler moves the joint by at most h (v + h alpha) past
    # it in one substep h = dt / substeps, so the overshoot is at most omega h + alpha h^2: omega the speed
    # at the limit by energy conservation from rest at the start angle (the integrator only loses energy
    # here), alpha <= m g (L/2) / I.
    start = start_fraction * limit
    dt = 1e-3
    h = dt / substeps
    omega = math.sqrt(2 * ROD_MASS * G * ROD_LENGTH / 2 * (math.cos(start) - math.cos(limit)) / ROD_INERTIA)
    alpha = ROD_MASS * G * ROD_LENGTH / 2 / ROD_INERTIA
    model = inverted_pendulum((-limit, limit))
    sim = lk.Simulation(model, dt=dt, substeps=substeps)
    sim.q = [side * start]
    high, low = joint_excursion(sim, 800)
    overshoot = high - limit if side > 0 else -limit - low
    assert overshoot <= omega * h + alpha * h * h
    # It reached the limit (within 0.8 s from >= 0.3 of it) and rests there.
    assert overshoot > -1e-6
    assert abs(sim.q[0] - side * limit) < 1e-4 and abs(sim.v[0]) < 1e-2


def test_limits_from_urdf_stop_the_pendulum_and_dynamics_ignore_them():
    xml = f"""<robot name="p"><link name="base"/>
      <link name="rod"><inertial><origin xyz="0 0 {ROD_LENGTH / 2}"/><mass value="{ROD_MASS}"/>
        <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.001"/></inertial></link>
      <joint name="hinge" type="revolute"><parent link="base"/><child link="rod"/><axis xyz="0 1 0"/>
        <limit lower="-0.5" upper="0.5" effort="7" velocity="3"/></joint></robot>"""
    model = lk.Model.from_urdf(xml)
    assert model.limits("rod") == {"lower": -0.5, "upper": 0.5, "effort": 7.0, "velocity": 3.0}
    assert model.limits(0) is None
    sim = lk.Simulation(model)
    sim.q = [0.4]
    high, _ = joint_excursion(sim, 1000)
    # One 1 ms step at the impact speed bounds the overshoot: omega h + alpha h^2 ~ 1.64e-3 rad for this rod
    # (I = 0.0825 kg m^2 about the hinge: omega ~ 1.61 rad/s from 0.4 rad, alpha <= 30 rad/s^2).
    assert 0.5 - 1e-6 < high <= 0.5 + 2e-3
    # The dynamics algorithms ignore limits: outside its range the joint accelerates as if unlimited.
    free = lk.Model.from_urdf(xml.replace('<limit lower="-0.5" upper="0.5" effort="7" velocity="3"/>', ""))
    assert free.limits(1) is None
    q, v, tau = np.array([1.0]), np.array([0.3]), np.array([20.0])
    np.testing.assert_array_equal(lk.aba(model, q, v, tau), lk.aba(free, q, v, tau))


def test_effort_limit_clips_the_actuation():
    limited = inverted_pendulum({"effort": 1.5})
    assert limited.limits(1) == {"lower": -math.inf, "upper": math.inf, "effort": 1.5, "velocity": math.inf}
    sim = lk.Simulation(limited)
    sim.step([10.0])
    assert sim.applied_tau.tolist() == [1.5]
    sim.step([-10.0])
    assert sim.applied_tau.tolist() == [-1.5]
    # The tighter of the servo's torque limit and the effort limit applies.
    sim.set_servo(kp=5.0, torque_limit=3.0, target_q=[0.0])
    sim.step([10.0])
    assert sim.applied_tau.tolist() == [1.5]
    sim.set_servo(kp=5.0, torque_limit=1.0, target_q=[0.0])
    sim.step([10.0])
    assert sim.applied_tau.tolist() == [1.0]
    # The clipped torque is what moves the joint: the same motion as commanding 1.5 N m without a bound.
    bounded, unbounded = lk.Simulation(limited), lk.Simulation(inverted_pendulum())
    bounded.step([10.0], n=200)
    unbounded.step([1.5], n=200)
    np.testing.assert_array_equal(bounded.q, unbounded.q)
    np.testing.assert_array_equal(bounded.v, unbounded.v)


def test_limits_arguments_are_checked_and_read_back():
    model = lk.Model(floating_base=False)
    hinge = model.add_revolute(0, [0, 1, 0], limits=np.array([-1.0, 2.0]))
    slider = model.add_prismatic(hinge, [0, 0, 1], limits={"lower": -0.1, "velocity": 0.5})
    fixed = model.add_fixed(slider)
    assert model.limits(hinge) == {"lower": -1.0, "upper": 2.0, "effort": math.inf, "velocity": math.inf}
    assert model.limits(slider) == {"lower": -0.1, "upper": math.inf, "effort": math.inf, "velocity": 0.5}
    assert model.limits(fixed) is None and model.limits(0) is None
    unlimited = model.add_revolute(0, [1, 0, 0], limits={})
    assert model.limits(unlimited) is None
    nbodies = model.nbodies
    for bad, error in [
        ((1.0, -1.0), ValueError), ((0.0, 1.0, 2.0), ValueError), ({"effort": 0.0}, ValueError),
        ({"velocity": -1.0}, ValueError), ({"lower": math.nan}, ValueError), ({"upper": -math.inf}, ValueError),
        ({"lowr": 1.0}, ValueError), ({"lower": "x"}, TypeError), ("ab", TypeError), (3.0, TypeError),
    ]:
        with pytest.raises(error, match="limits"):
            model.add_revolute(0, [0, 1, 0], limits=bad)
    assert model.nbodies == nbodies
