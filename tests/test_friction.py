"""Coulomb friction in the tree engine (friction_law="coulomb", the default) against closed-form physics, to the step.

A launched box (deceleration μg from the first step, stopping distance, no hop), a box on an incline at μ
just below and just above tan θ (acceleration g (sin θ − μ cos θ), hover, creep), a sphere launched without
spin (the 2/7 rule: it rolls at 5/7 of its speed after 2 v0 / (7 μ g)) and on an incline (rolls without slip
while μ > 2/7 tan θ, slides below), and a pendulum's period and first-order energy error. Each tolerance is
derived in its test from the scheme (semi-implicit Euler, one impulse per contact per step) and the solver's
convergence (relative 1e-10), never read off a run.
"""

import math

import numpy as np
import pytest

import legkit as lk

G = lk.STANDARD_GRAVITY
DT = 1e-3
SIZE = 0.2  # box edge (m)
# The Newton solver stops at a gradient 1e-10 of the contacts' impulses; friction and normal impulses, and
# so a step's velocity change, are exact to far better than this relative bound, kept loose for rounding
# over hundreds of steps.
SOLVER_RTOL = 1e-6


def box_sim(mu, gravity=None, size=SIZE):
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(1.0, [size] * 3), gravity=gravity)
    sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(mu), shapes={0: ("box", [size] * 3)})
    sim.q = [0.0, 0.0, size / 2, 0.0, 0.0, 0.0, 1.0]
    sim.step(n=200)  # settled: its contacts carry its weight, warm-started
    return sim


def world_velocity(sim):
    """The base's linear velocity in world axes (sim.v holds it in the base frame)."""
    return sim.body_poses()[0][:3, :3] @ sim.v[:3]


@pytest.mark.parametrize("v0, mu", [(2.0, 0.8), (1.0, 0.4)])
def test_launched_box_decelerates_at_mu_g_and_stops_at_v2_over_2_mu_g_without_a_hop(v0, mu):
    sim = box_sim(mu)
    rest = sim.q.copy()
    v = sim.v.copy()
    v[0] = v0
    sim.v = v
    deceleration = mu * G
    steps = int(v0 / (deceleration * DT)) + 100
    heights, speeds, ratios, pushes = [], [v0], [], []
    for _ in range(steps):
        sim.step()
        heights.append(sim.q[2])
        speeds.append(world_velocity(sim)[0])
        contacts = sim.contacts()
        loaded = contacts["normal_force"] > 0
        ratios.extend(np.linalg.norm(contacts["tangential_force"][loaded], axis=1) / contacts["normal_force"][loaded])
        pushes.append(contacts["tangential_force"][:, 0].sum())
    speeds = np.array(speeds)
    sliding = int(v0 / (deceleration * DT))
    drops = -np.diff(speeds[: sliding + 1]) / DT
    # Sliding, each corner's friction is μ λ_n exactly (the disk's rim), and it alone changes the speed.
    np.testing.assert_allclose(ratios[: 4 * (sliding - 1)], mu, rtol=1e-9)
    np.testing.assert_allclose(drops, -np.array(pushes[:sliding]), rtol=SOLVER_RTOL)
    # The corners' normal impulses sum to m g h but while the load shift that the friction's moment makes
    # (front corners pressed deeper into their soft, R = ε A, ε = 1e-2, normal rows) settles: resting
    # depths are ε g h² / β, and moving a share ≤ μ c / a = μ of them changes Σ λ_n by at most ε μ m g h.
    # So the deceleration is μ g within ε μ from the first step (the issue asks 2 % from the second).
    assert np.abs(drops / deceleration - 1).max() <= mu * 1e-2
    assert abs(speeds[-1]) < 1e-9, "the box stops and stays stopped"
    # Semi-implicit Euler moves by h v_k after each velocity update: the distance is h Σ_{k≥1} v_k, which
    # is v0²/(2μg) − v0 h / 2 up to the last partial step (at most μ g h² / 2).
    travelled = sim.q[0] - rest[0]
    discrete = DT * speeds[1:].clip(0).sum()
    continuous = v0**2 / (2 * deceleration)
    # (q is integrated on SE(3) from the base-frame velocity: the friction's pitch, ~1e-5 rad, turns it.)
    assert abs(travelled - discrete) <= 1e-5 * continuous
    assert abs(travelled - (continuous - v0 * DT / 2)) <= deceleration * DT**2
    assert abs(travelled / continuous - 1) <= 0.01
    # No hop: nothing asks the normal rows for a separating velocity; the only upward push is the
    # Baumgarte term's, on a resting penetration within the contact tolerance.
    assert max(heights) - rest[2] <= sim.contact_tolerance
    assert abs(sim.q[2] - rest[2]) <= sim.contact_tolerance


ALPHA = 0.3  # incline angle (rad): tan = 0.3093


def incline_sim(mu):
    """The box on the plane z = 0 under gravity tilted by ALPHA toward +x: an incline in its own frame."""
    return box_sim(mu, gravity=[G * math.sin(ALPHA), 0.0, -G * math.cos(ALPHA)])


def test_box_just_below_the_friction_angle_slides_at_g_sin_minus_mu_cos_without_hovering():
    mu = 0.98 * math.tan(ALPHA)
    sim = incline_sim(mu)
    rest_height = sim.q[2]
    expected = G * (math.sin(ALPHA) - mu * math.cos(ALPHA))  # 0.058 m/s²: a hard case for the ratio
    speeds, heights = [], []
    for _ in range(1000):
        sim.step()
        speeds.append(world_velocity(sim)[0])
        heights.append(sim.q[2])
    # Every step adds h g (sin θ − μ cos θ) once all four corners slide (from the settling run's last
    # steps on): the friction impulse is μ λ_n with Σ λ_n = m g cos θ h to the solver's tolerance, which
    # the small difference sin θ − μ cos θ amplifies by μ cos θ / (sin θ − μ cos θ) ≈ 49.
    accelerations = np.diff(speeds) / DT
    np.testing.assert_allclose(accelerations, expected, rtol=50 * SOLVER_RTOL)
    assert abs(np.polyfit(np.arange(len(speeds)) * DT, speeds, 1)[0] / expected - 1) <= 1e-3
    # Hover: the sliding box stays at its resting height to within the contact tolerance's share the
    # Baumgarte term leaves (issue target 0.05 mm).
    assert max(abs(h - rest_height) for h in heights) <= 0.05e-3


def test_box_just_above_the_friction_angle_sticks_without_creep():
    mu = 1.02 * math.tan(ALPHA)
    sim = incline_sim(mu)
    start = sim.q[0]
    sim.step(n=1000)
    # Friction regularised towards last step's impulse (proximal) holds a loaded contact still once warm:
    # any creep would be ε = 1e-2 of the velocity gravity builds in one step, 4e-5 m/s, and only on the
    # first step; over 1 s the box moves far less than the 0.1 mm/s target.
    creep = (sim.q[0] - start) / 1.0
    assert abs(creep) <= 1e-4
    assert abs(world_velocity(sim)[0]) <= 1e-4


RADIUS = 0.1


def sphere_sim(mu, gravity=None):
    mass = 1.0
    inertia = 0.4 * mass * RADIUS**2 * np.eye(3)
    model = lk.Model(floating_base=True, base=lk.MassProperties(mass, [0.0, 0.0, 0.0], inertia), gravity=gravity)
    sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(mu), shapes={0: ("sphere", RADIUS)})
    sim.q = [0.0, 0.0, RADIUS, 0.0, 0.0, 0.0, 1.0]
    sim.step(n=100)
    return sim


def step_sphere(sim):
    """One step; the sphere's velocity in the world and its contact point's tangential velocity (its slip,
    zero when rolling), both in the frame of the pose the step started from, where the engine's constraint
    rows are (with the pose after it, the base-frame velocity reads turned by h ω: a slip of h ω v / 2)."""
    pose = sim.body_poses()[0]
    sim.step()
    linear, angular = pose[:3, :3] @ sim.v[:3], pose[:3, :3] @ sim.v[3:]
    point = sim.contacts()["point"][0]  # found at the step's start, as deep as the sphere rests
    slip = linear + np.cross(angular, point - pose[:3, 3])
    return linear, slip[:2]


def coriolis_growth(omega_rate, steps):
    """The relative speed a spinning free body gains in `steps` steps while its spin grows at `omega_rate`:
    its base-frame velocity is turned by the Coriolis term −ω × v explicitly, I − h [ω]× instead of a
    rotation, which lengthens it by (h ω)² / 2 per step: Σ_k (h ω_k)² / 2 with ω_k = k h ω̇."""
    return sum((DT * k * DT * omega_rate) ** 2 / 2 for k in range(1, steps + 1))


@pytest.mark.parametrize("mu", [0.2, 0.5])
def test_sphere_launched_without_spin_rolls_at_five_sevenths_after_two_sevenths(mu):
    sim = sphere_sim(mu)
    v0 = 2.0
    v = sim.v.copy()
    v[:3] = sim.body_poses()[0][:3, :3].T @ [v0, 0.0, 0.0]
    sim.v = v
    # Sliding: dv/dt = −μ g, dω/dt = 5 μ g / (2 r) (torque μ m g r on (2/5) m r²), until v = ω r at
    # t* = 2 v0 / (7 μ g), then rolling at 5/7 v0 with no friction. In steps: the slip drops by
    # (7/2) μ g h per step, and the last sliding step's impulse is cut to what makes it roll.
    t_roll = 2 * v0 / (7 * mu * G)
    sliding_steps = int(t_roll / DT)
    slips, speeds = [], []
    for _ in range(sliding_steps + 20):
        linear, slip = step_sphere(sim)
        slips.append(np.linalg.norm(slip))
        speeds.append(linear[0])
    assert slips[sliding_steps - 2] > 3 * mu * G * DT  # still sliding one step before t*
    # Rolling from the step after t*: friction regularised towards last step's (proximal) lets the first
    # sticking steps keep ε = 1e-2 of the slip the step before left (at most (7/2) μ g h), each step ε of
    # the last: below 1e-6 m/s three steps on.
    assert max(slips[sliding_steps + 1 :]) <= 1e-2 * 3.5 * mu * G * DT
    assert max(slips[sliding_steps + 4 :]) <= 1e-6
    # 5/7 v0, up to the speed the explicit Coriolis term adds while the spin builds up (≤ 0.4 %).
    growth = coriolis_growth(5 * mu * G / (2 * RADIUS), sliding_steps + 1)
    assert abs(speeds[sliding_steps + 1] / (5 / 7 * v0) - 1) <= 2 * growth + SOLVER_RTOL


@pytest.mark.parametrize("ratio", [0.9, 1.1])
def test_sphere_on_an_incline_rolls_iff_mu_exceeds_two_sevenths_tan(ratio):
    mu = ratio * 2 / 7 * math.tan(ALPHA)
    sim = sphere_sim(mu, gravity=[G * math.sin(ALPHA), 0.0, -G * math.cos(ALPHA)])
    speeds, slips = [], []
    steps = 300
    for _ in range(steps):
        linear, slip = step_sphere(sim)
        speeds.append(linear[0])
        slips.append(slip[0])
    times = np.arange(steps) * DT
    acceleration = np.polyfit(times, speeds, 1)[0]
    if ratio > 1:
        # Rolling needs friction (2/7) m g sin θ ≤ μ m g cos θ: acceleration (5/7) g sin θ, no slip.
        expected = 5 / 7 * G * math.sin(ALPHA)
        omega_rate = expected / RADIUS
        assert max(np.abs(slips)) <= 1e-5
    else:
        # Sliding: a = g (sin θ − μ cos θ), the slip growing at g sin θ − (7/2) μ g cos θ.
        expected = G * (math.sin(ALPHA) - mu * math.cos(ALPHA))
        omega_rate = 5 * mu * G * math.cos(ALPHA) / (2 * RADIUS)
        slip_rate = G * math.sin(ALPHA) - 3.5 * mu * G * math.cos(ALPHA)
    # Each step adds h a (a constant impulse per step in both regimes), so a linear fit is exact but for
    # the explicit Coriolis term's lengthening of the velocity (`coriolis_growth`), which also presses
    # the spinning sphere into the ground a little harder.
    tolerance = 2 * coriolis_growth(omega_rate, steps) + 1e-4
    assert abs(acceleration / expected - 1) <= tolerance
    if ratio < 1:
        # The slip rate a − α r is a difference of two such rates: its error is theirs times
        # (a + α r) / (a − α r).
        amplification = (expected + omega_rate * RADIUS) / slip_rate
        assert abs(np.polyfit(times, slips, 1)[0] / slip_rate - 1) <= amplification * tolerance


def test_pendulum_period_and_first_order_energy_error():
    # A point-like bob (a small dense cube) at length l on a revolute joint about y, released at θ0.
    length, mass, side = 0.5, 1.0, 0.01
    model = lk.Model(floating_base=False)
    bob = lk.MassProperties.solid_box(mass, [side] * 3, center=[0.0, 0.0, -length])
    model.add_revolute(0, [0.0, 1.0, 0.0], (np.eye(3), [0.0, 0.0, 0.0]), bob)
    inertia = mass * length**2 + mass * side**2 / 6
    omega = math.sqrt(mass * G * length / inertia)
    theta0 = 0.05

    def run(dt, periods=10):
        sim = lk.Simulation(model, dt=dt)
        sim.q = [theta0]
        angles, energies = [theta0], []
        n = int(periods * 2 * math.pi / omega / dt)
        for _ in range(n):
            sim.step()
            theta, rate = sim.q[0], sim.v[0]
            angles.append(theta)
            energies.append(0.5 * inertia * rate**2 + mass * G * length * (1 - math.cos(theta)))
        return np.array(angles), np.array(energies)

    angles, energies = run(DT)
    # Period from the downward zero crossings, linearly interpolated (the angle is straight there).
    signs = np.signbit(angles)
    crossings = np.nonzero(~signs[:-1] & signs[1:])[0]
    times = (crossings + angles[crossings] / (angles[crossings] - angles[crossings + 1])) * DT
    period = np.mean(np.diff(times))
    # T = 2π/ω (1 + θ0²/16 + O(θ0⁴)); semi-implicit Euler shifts the frequency by (ωh)²/24 (its map's
    # trace 2 − (ωh)²): 2e-6 relative here, and θ0⁴ terms 2e-8; interpolating crossings of a sine at 1 kHz
    # is exact to O((ωh)³). 1e-4 bounds them all with margin.
    expected = 2 * math.pi / omega * (1 + theta0**2 / 16)
    assert abs(period / expected - 1) <= 1e-4
    # Symplectic Euler keeps a modified energy: the true energy oscillates, relative amplitude ≤ ωh / 2,
    # without drift; first order, so halving h halves it.
    e0 = mass * G * length * (1 - math.cos(theta0))
    error = np.abs(energies / e0 - 1).max()
    assert error <= omega * DT / 2 * 1.05
    _, finer = run(DT / 2)
    ratio = error / np.abs(finer / e0 - 1).max()
    assert 1.8 <= ratio <= 2.2


def test_the_cone_law_lifts_a_sliding_box_and_coulombs_does_not():
    # The convex relaxation (friction_law="cone") makes a sliding contact separate at
    # v_n = μ |v_t| (less what its soft normal row absorbs): launched at 2 m/s with μ = 0.8, the box leaves
    # the ground in its first step at nearly μ times its new speed. Coulomb's law keeps it down.
    heights = {}
    for law in ("cone", "coulomb"):
        model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(1.0, [SIZE] * 3))
        sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(0.8), shapes={0: ("box", [SIZE] * 3)}, friction_law=law)
        assert sim.friction_law == law
        sim.q = [0.0, 0.0, SIZE / 2, 0.0, 0.0, 0.0, 1.0]
        sim.step(n=200)
        rest = sim.q[2]
        sim.v = [2.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        sim.step()
        velocity = world_velocity(sim)
        if law == "cone":
            assert velocity[2] > 0.5 * 0.8 * velocity[0]
        sim.step(n=20)
        heights[law] = sim.q[2] - rest
    assert heights["cone"] > 10e-3 and heights["coulomb"] <= 1e-6


def test_a_box_pushed_back_and_forth_inside_its_cone_sticks_and_takes_one_newton_step_a_step():
    # A bar on the ground pushed by a horizontal force that swings inside μ m g (4 N and 2 N against 7.8 N).
    # Every corner sticks every step, where the law is affine: the solver's first step, taken in the zones of
    # the warm start's impulses (last step's), lands on the solution, so each step takes one Newton iteration
    # (Newton from the zones at the warm start's own velocities takes two on some steps).
    size = [0.4, 0.1, 0.1]
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(1.0, size))
    sim = lk.Simulation(model, dt=DT, ground=lk.Ground.plane(0.8), shapes={0: ("box", size)})
    sim.q = [0.0, 0.0, size[2] / 2, 0.0, 0.0, 0.0, 1.0]
    sim.step(n=200)
    start = sim.q.copy()
    for k in range(1000):
        push = np.array([4.0 * math.sin(4 * math.pi * k * DT), 2.0 * math.sin(6 * math.pi * k * DT), 0.0])
        sim.step(np.concatenate([push, np.zeros(3)]))
        assert sim.last_solver_iterations == 1, f"step {k}"
        # Friction balances the push (the base frame is the world's while the bar lies flat) but for the
        # momentum the regularised corners let the bar take up: a sticking corner's friction is drawn towards
        # last step's with R = 1e-2 of its Delassus diagonal (at most 1/m + 0.2² / I_zz + 0.05² / I_xx = 5.3/kg
        # across the bar), so a change Δ of the push in a step leaves at most m R Δ unbalanced, with Δ at most
        # 4 N × 4π/s × 1 ms = 0.05 N.
        friction = sim.contacts()["tangential_force"].sum(axis=0)
        np.testing.assert_allclose(friction[:2], -push[:2], atol=1e-2 * 5.3 * 0.05)
    # No creep: the regularisation's share only, far below the 0.1 mm/s target.
    assert np.abs(sim.q[:2] - start[:2]).max() <= 1e-6


def test_coulombs_law_is_the_default():
    # What a new user's box slides under (the closed-form tests above build their simulations without the argument).
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(1.0, [SIZE] * 3))
    assert lk.Simulation(model).friction_law == "coulomb"


def test_an_unknown_friction_law_is_refused_naming_it():
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(1.0, [SIZE] * 3))
    with pytest.raises(ValueError, match="friction_law"):
        lk.Simulation(model, friction_law="tresca")
