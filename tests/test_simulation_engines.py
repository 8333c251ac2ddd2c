"""legkit's tree engine (backend="tree") against Rapier (backend="rapier") and against physics.

Cross-checks on scenes with closed-form answers: statics (contact forces carry the weight), free fall and
landing, tipping past the critical angle, Coulomb friction on an incline; convergence of free motion to
ABA + RK4; the divergence guard; SimulationBatch; determinism and reset; the self-collision switch.
Every reference is computed here from the scene's numbers, never read back from the engine.
"""

import math
import threading

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from test_simulation import FOOT_RADIUS, LEG_LENGTH, quadruped, rotation, ten_link_tree, total_contact_force

G = lk.STANDARD_GRAVITY
BACKENDS = ("tree", "rapier")


def quaternion_about_y(angle):
    """[qx, qy, qz, qw] of a rotation by `angle` about the world y axis."""
    return [0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)]


def free_box(mass, size, backend, ground, gravity=None, shapes=None, dt=1e-3):
    model = lk.Model(floating_base=True, base=lk.MassProperties.solid_box(mass, list(size)), gravity=gravity)
    return model, lk.Simulation(model, dt=dt, ground=ground, shapes=shapes, backend=backend)


def settle_quadruped(backend, steps=2000):
    """The quadruped of test_simulation on servos, placed with its feet just above the plane, after `steps`."""
    model, shapes = quadruped()
    sim = lk.Simulation(model, dt=1e-3, ground=lk.Ground.plane(0.8), shapes=shapes, backend=backend)
    q = model.neutral()
    q[2] = 0.03 + 2 * LEG_LENGTH + FOOT_RADIUS + 0.005
    sim.q = q
    sim.set_servo(kp=40.0, kd=0.3, torque_limit=20.0, target_q=model.neutral())
    sim.step(n=steps)
    return model, sim


# ------------------------------------------------------------------------------------------------------
# 1a. Statics: the contact forces of a body at rest sum to its weight
# ------------------------------------------------------------------------------------------------------

# Relative error of the summed contact force against the weight, once at rest.
TREE_FORCE_RTOL = 1e-6
RAPIER_FORCE_RTOL = 1e-3
# Both engines put a resting body's COM at the same height to within this (m).
COM_AGREEMENT = 3e-3


@examples(8)
@given(st.floats(0.1, 30.0), st.tuples(st.floats(0.05, 0.5), st.floats(0.05, 0.5), st.floats(0.03, 0.4)))
def test_resting_box_contact_forces_sum_to_its_weight_on_both_engines(mass, size):
    # Boxes that rest: at most twice as tall as their narrower side. A slab standing on edge (5 cm by
    # 31 cm tall) still rocks on Rapier after the 1 s allowed here.
    assume(size[2] <= 2.0 * min(size[0], size[1]))
    weight = mass * G
    heights = {}
    for backend in BACKENDS:
        _, sim = free_box(mass, size, backend, lk.Ground.plane(0.8))
        sim.q = [0.0, 0.0, size[2] / 2 + 1e-4, 0.0, 0.0, 0.0, 1.0]
        sim.step(n=1000)
        assert np.abs(sim.v).max() < 1e-3, f"{backend}: the box should be at rest after 1 s, v = {sim.v}"
        contacts = sim.contacts()
        force = total_contact_force(contacts)
        rtol = TREE_FORCE_RTOL if backend == "tree" else RAPIER_FORCE_RTOL
        assert abs(force[2] - weight) <= rtol * weight, f"{backend}: vertical force {force[2]!r} vs weight {weight!r}"
        assert np.abs(force[:2]).max() <= rtol * weight, f"{backend}: horizontal force {force[:2]}"
        # The box rests on its face: the COM is half its height up, less at most the tolerated penetration.
        sink = size[2] / 2 - sim.q[2]
        assert -1e-9 <= sink <= sim.contact_tolerance, f"{backend}: COM {sink} m below the resting height"
        heights[backend] = sim.q[2]
    assert abs(heights["tree"] - heights["rapier"]) <= COM_AGREEMENT


def test_standing_quadruped_carries_its_weight_and_both_engines_agree_on_its_com_height():
    total_mass = 4.0 + 4 * (0.3 + 0.2)
    weight = total_mass * G
    model, _ = quadruped()
    # The reference: legs straight down (the servo targets), ball feet touching z = 0.
    q_ref = model.neutral()
    q_ref[2] = 0.03 + 2 * LEG_LENGTH + FOOT_RADIUS
    com_ref = lk.center_of_mass(model, q_ref)[2]
    com = {}
    for backend in BACKENDS:
        model, sim = settle_quadruped(backend)
        assert np.abs(sim.v).max() < 1e-3, f"{backend}: not at rest, v = {sim.v}"
        contacts = sim.contacts()
        assert set(contacts["body"]) == {2, 4, 6, 8} and set(contacts["other"]) == {-1}
        force = total_contact_force(contacts)
        rtol = TREE_FORCE_RTOL if backend == "tree" else RAPIER_FORCE_RTOL
        assert abs(force[2] - weight) <= rtol * weight, f"{backend}: vertical force {force[2]!r} vs weight {weight!r}"
        assert np.abs(force[:2]).max() <= rtol * weight
        com[backend] = lk.center_of_mass(model, sim.q)[2]
        assert abs(com[backend] - com_ref) <= COM_AGREEMENT, f"{backend}: COM height {com[backend]} vs {com_ref}"
    assert abs(com["tree"] - com["rapier"]) <= COM_AGREEMENT


# ------------------------------------------------------------------------------------------------------
# 1b. A drop lands at sqrt(2 h / g) and comes to rest on the surface
# ------------------------------------------------------------------------------------------------------


@examples(8)
@given(
    st.floats(0.005, 1.2),
    st.floats(0.1, 20.0),
    st.sampled_from(["sphere", "box"]),
    st.floats(0.02, 0.15),
)
def test_dropped_body_lands_at_the_free_fall_time_and_rests_on_the_ground(drop, mass, kind, half):
    # `drop` is the gap between the body's lowest point and the plane; `half` its radius or half edge.
    dt = 1e-3
    landing = math.sqrt(2 * drop / G)
    shapes = {0: ("sphere", half) if kind == "sphere" else ("box", (2 * half, 2 * half, 2 * half))}
    for backend in BACKENDS:
        _, sim = free_box(mass, (2 * half,) * 3, backend, lk.Ground.plane(0.8), shapes=shapes, dt=dt)
        sim.q = [0.0, 0.0, half + drop, 0.0, 0.0, 0.0, 1.0]
        touched = None
        for _ in range(int(landing / dt) + 50):
            sim.step()
            if sim.contacts()["normal_force"].sum() > 0.0:
                touched = sim.time
                break
        assert touched is not None, f"{backend}: no contact force within 50 steps of t = {landing}"
        assert abs(touched - landing) <= 2 * dt, f"{backend}: landed at {touched} s, free fall says {landing} s"
        sim.step(n=600)
        assert np.abs(sim.v).max() < 1e-2, f"{backend}: not at rest 0.6 s after landing, v = {sim.v}"
        if backend == "tree":
            penetration = half - sim.q[2]
            assert penetration <= 1e-3, f"penetration {penetration} m at rest"
            assert sim.contacts()["depth"].max() <= 1e-3


# ------------------------------------------------------------------------------------------------------
# 1c. A tall box released on an edge tips over iff its COM is beyond that edge
# ------------------------------------------------------------------------------------------------------


@examples(10)
@given(
    st.floats(0.05, 0.2),
    st.floats(1.5, 5.0),
    st.floats(0.06, 0.4),
    st.sampled_from([1.0, -1.0]),
)
def test_box_released_on_its_edge_tips_over_iff_past_the_critical_angle_on_both_engines(width, aspect, offset, side):
    height = aspect * width
    critical = math.atan(width / height)  # the COM is straight above the edge
    tilt = min(max(critical + side * offset, 0.02), 1.3)
    tips = tilt > critical
    # Rotated by `tilt` about y, the box's lowest edge is (x = w/2, z = -h/2); put it 0.1 mm above z = 0.
    z = width / 2 * math.sin(tilt) + height / 2 * math.cos(tilt) + 1e-4
    outcome = {}
    for backend in BACKENDS:
        _, sim = free_box(1.0, (width, width, height), backend, lk.Ground.plane(0.8))
        sim.q = [0.0, 0.0, z] + quaternion_about_y(tilt)
        sim.step(n=2000)
        axis = sim.body_poses()[0][:3, 2]  # the box's long axis in the world
        if axis[2] > math.cos(critical):
            outcome[backend] = "upright"
        elif axis[0] > math.cos(0.05):
            outcome[backend] = "on its side"  # fallen about the edge it was released on, toward +x
        else:
            outcome[backend] = f"neither (long axis {axis})"
    expected = "on its side" if tips else "upright"
    assert outcome == {"tree": expected, "rapier": expected}, f"tilt {tilt} rad, critical {critical} rad"


# ------------------------------------------------------------------------------------------------------
# 1d. Coulomb friction on an incline
# ------------------------------------------------------------------------------------------------------

BOX = (0.2, 0.2, 0.1)
BOX_MASS = 2.0


def incline(alpha, mu, ground_kind, backend="tree", start=-2.0):
    """A box resting flat on a slope of angle alpha descending toward +x, released 0.1 mm above it.

    "heightfield": the slope is terrain (heights linear in x) under normal gravity; "tilted_gravity": the
    plane z = 0 under gravity g (sin alpha, 0, -cos alpha), the same physics in the slope's frame.
    Returns (sim, down-slope unit vector in the world).
    """
    if ground_kind == "heightfield":
        cell, n = 0.05, 121
        x = (np.arange(n) - (n - 1) / 2) * cell
        heights = np.tile(-math.tan(alpha) * x[:, None], (1, 21))
        _, sim = free_box(BOX_MASS, BOX, backend, lk.Ground.heightfield(heights, cell, friction=mu))
        # Box centre a half height along the slope normal (sin a, 0, cos a) from the surface point at `start`.
        centre = np.array([start, 0.0, -math.tan(alpha) * start]) + (BOX[2] / 2 + 1e-4) * np.array([math.sin(alpha), 0, math.cos(alpha)])
        sim.q = list(centre) + quaternion_about_y(alpha)
        return sim, np.array([math.cos(alpha), 0.0, -math.sin(alpha)])
    gravity = [G * math.sin(alpha), 0.0, -G * math.cos(alpha)]
    _, sim = free_box(BOX_MASS, BOX, backend, lk.Ground.plane(mu), gravity=gravity)
    sim.q = [0.0, 0.0, BOX[2] / 2 + 1e-4, 0.0, 0.0, 0.0, 1.0]
    return sim, np.array([1.0, 0.0, 0.0])


def slide(sim, down, seconds=1.0, skip=0.1):
    """(times, down-slope displacements from the start) after `skip` s of settling, one sample per step."""
    start = sim.q[:3].copy()
    times, positions = [], []
    for _ in range(int(round(seconds / sim.dt))):
        sim.step()
        if sim.time >= skip - 1e-12:
            times.append(sim.time)
            positions.append((sim.q[:3] - start) @ down)
    return np.array(times), np.array(positions), sim.q[:3] - start


@pytest.mark.parametrize("ground_kind", ["heightfield", "tilted_gravity"])
@pytest.mark.parametrize("alpha, ratio", [(0.2, 1.5), (0.35, 1.2)])
def test_box_on_an_incline_with_friction_above_its_slope_stays_put(ground_kind, alpha, ratio):
    mu = ratio * math.tan(alpha)
    sim, down = incline(alpha, mu, ground_kind)
    _, _, displacement = slide(sim, down, seconds=1.0)
    assert np.linalg.norm(displacement) < 1e-3, f"moved {displacement} m with mu = {mu} > tan(alpha) = {math.tan(alpha)}"


def sliding_acceleration(alpha, mu, ground_kind):
    """(measured, expected) down-slope acceleration of the box over 0.1-1 s, and the simulation."""
    expected = G * (math.sin(alpha) - mu * math.cos(alpha))
    sim, down = incline(alpha, mu, ground_kind)
    times, s, _ = slide(sim, down, seconds=1.0)
    # Constant acceleration: s(t) is a parabola whose second derivative is the acceleration.
    measured = 2 * np.polyfit(times, s, 2)[0]
    return measured, expected, sim


@examples(6)
@given(st.floats(0.15, 0.5), st.floats(0.1, 0.7))
def test_box_sliding_down_a_tilted_gravity_plane_accelerates_at_g_sin_minus_mu_cos(alpha, fraction):
    mu = fraction * math.tan(alpha)
    measured, expected, sim = sliding_acceleration(alpha, mu, "tilted_gravity")
    # Coulomb: at a sliding contact the friction is mu N, opposite that point's slip velocity.
    pose = sim.body_poses()[0]
    base_rotation, origin = pose[:3, :3], pose[:3, 3]
    linear, angular = base_rotation @ sim.v[:3], base_rotation @ sim.v[3:]
    contacts = sim.contacts()
    loaded = contacts["normal_force"] > 1e-6
    slip = linear + np.cross(angular, contacts["point"][loaded] - origin)
    slip -= (slip * contacts["normal"][loaded]).sum(1)[:, None] * contacts["normal"][loaded]
    friction = contacts["tangential_force"][loaded]
    cosines = -(friction * slip).sum(1) / (np.linalg.norm(friction, axis=1) * np.linalg.norm(slip, axis=1))
    angles = np.degrees(np.arccos(np.clip(cosines, -1, 1)))
    ratios = np.linalg.norm(friction, axis=1) / contacts["normal_force"][loaded]
    # One assertion for both, so that hypothesis reports (and shrinks) one failure.
    assert abs(measured - expected) <= 0.03 * expected and np.all(angles < 2.0), (
        f"alpha {alpha}, mu {mu}: acceleration {measured} m/s^2, g (sin - mu cos) = {expected} m/s^2 "
        f"(friction delivered {(G * math.sin(alpha) - measured) / (G * math.cos(alpha))} x N instead of {mu}); "
        f"at the end, per contact |friction| / N = {ratios.round(4).tolist()}, angle between friction and "
        f"-slip {angles.round(1).tolist()} degrees"
    )


@pytest.mark.parametrize("alpha, mu", [(0.3, 0.1)])
def test_box_sliding_down_an_inclined_heightfield_accelerates_at_g_sin_minus_mu_cos(alpha, mu):
    expected = G * (math.sin(alpha) - mu * math.cos(alpha))
    sim, down = incline(alpha, mu, "heightfield")
    # The terrain is one plane: every loaded contact should push along its normal (sin a, 0, cos a).
    slope_normal = np.array([math.sin(alpha), 0.0, math.cos(alpha)])
    start = sim.q[:3].copy()
    times, s, stray_steps, stray_normals, yaw_rate = [], [], 0, set(), 0.0
    for _ in range(1000):
        sim.step()
        contacts = sim.contacts()
        loaded = contacts["normal_force"] > 0
        stray = np.abs(contacts["normal"][loaded] @ slope_normal - 1) > 1e-6
        if stray.any():
            stray_steps += 1
            stray_normals |= {tuple(float(x) for x in n) for n in contacts["normal"][loaded][stray].round(2)}
        yaw_rate = max(yaw_rate, abs(sim.v[5]))
        if sim.time >= 0.1 - 1e-12:
            times.append(sim.time)
            s.append((sim.q[:3] - start) @ down)
    measured = 2 * np.polyfit(times, s, 2)[0]
    diagnosis = (
        f"travelled {s[-1]:.4f} m in 1 s; {stray_steps} of 1000 steps had loaded contacts off the slope normal "
        f"{sorted(stray_normals)[:6]}; largest yaw rate {yaw_rate:.3f} rad/s"
    )
    assert abs(measured - expected) <= 0.03 * expected, (
        f"alpha {alpha}, mu {mu}: acceleration {measured} m/s^2, g (sin - mu cos) = {expected} m/s^2; {diagnosis}"
    )
    assert stray_steps == 0, diagnosis


# ------------------------------------------------------------------------------------------------------
# 2. Free motion converges to ABA + RK4 at first order
# ------------------------------------------------------------------------------------------------------


def random_chain(seed, helical=False):
    """A chain of 2-6 revolute joints on random axes; with ``helical``, about half of them helical instead."""
    rng = np.random.default_rng(seed)
    links = int(rng.integers(2, 7))
    model = lk.Model(floating_base=False)
    parent = 0
    for _ in range(links):
        placement = (rotation(rng.normal(size=3), rng.uniform(-1, 1)), rng.uniform(-0.3, 0.3, 3))
        body = lk.MassProperties.solid_box(rng.uniform(0.2, 2), rng.uniform(0.05, 0.4, 3), center=rng.uniform(-0.15, 0.15, 3))
        if helical and rng.random() < 0.5:
            parent = model.add_helical(parent, rng.normal(size=3), rng.uniform(-0.1, 0.1), placement, body)
        else:
            parent = model.add_revolute(parent, rng.normal(size=3), placement, body)
    return model, rng.uniform(-1.5, 1.5, links), rng.uniform(-1, 1, links)


def errors_against_rk4(model, q0, v0, seconds, substeps_list=(1,), dts=(1e-3,)):
    """Final-configuration error of the tree engine against a fine RK4 run, for each (dt, substeps)."""
    reference, _ = lk.free_rollout(model, q0, v0, 1e-4, int(round(seconds / 1e-4)), method="rk4")
    errors = []
    for dt in dts:
        for substeps in substeps_list:
            sim = lk.Simulation(model, dt=dt, substeps=substeps, backend="tree")
            sim.q, sim.v = q0, v0
            sim.step(n=int(round(seconds / dt)))
            errors.append(np.abs(sim.q - reference[-1]).max())
    return np.array(errors)


def test_free_tree_converges_to_aba_rk4_at_first_order_in_dt_and_in_substeps():
    model = ten_link_tree()
    q0 = 0.3 * np.sin(1.7 * np.arange(model.nq))
    v0 = np.zeros(model.nv)
    # RK4 at 1e-4 s is many orders more accurate than a first-order step of 1e-3 / 32.
    fine, _ = lk.free_rollout(model, q0, v0, 1e-4, 5000, method="rk4")
    finer, _ = lk.free_rollout(model, q0, v0, 5e-5, 10000, method="rk4")
    assert np.abs(fine[-1] - finer[-1]).max() < 1e-9
    by_substeps = errors_against_rk4(model, q0, v0, 0.5, substeps_list=(1, 2, 4, 8, 16, 32))
    by_dt = errors_against_rk4(model, q0, v0, 0.5, dts=(2e-3, 1e-3, 5e-4, 2.5e-4))
    for errors in (by_substeps, by_dt):
        ratios = errors[:-1] / errors[1:]
        assert np.all((ratios > 1.8) & (ratios < 2.2)), f"errors {errors}, ratios {ratios}"
    assert by_substeps[-1] < 1e-3


@examples(5)
@given(st.integers(0, 2**31 - 1), st.booleans())
def test_random_free_chain_error_halves_with_the_substep(seed, helical):
    model, q0, v0 = random_chain(seed, helical)
    errors = errors_against_rk4(model, q0, v0, 0.3, substeps_list=(4, 8, 16, 32))
    ratios = errors[:-1] / errors[1:]
    assert np.all((ratios > 1.8) & (ratios < 2.2)), f"errors {errors}, ratios {ratios}"


def test_rapier_refuses_a_helical_joint_with_a_runtime_error_naming_it():
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0, 1, 0], None, lk.MassProperties.solid_box(0.5, [0.1, 0.1, 0.1]), "arm")
    model.add_helical("arm", [0, 0, 1], 0.01, None, lk.MassProperties.solid_box(0.2, [0.05, 0.05, 0.05]), "screw")
    lk.Simulation(model, backend="tree").step(n=3)
    with pytest.raises(RuntimeError, match="helical joint \\(body 2\\)"):
        lk.Simulation(model, backend="rapier")


# ------------------------------------------------------------------------------------------------------
# 3. The divergence guard
# ------------------------------------------------------------------------------------------------------


def small_pendulum(backend):
    """A 0.1 kg, 0.1 m rod on a hinge about y: inertia about the hinge ~3.3e-4 kg m^2."""
    model = lk.Model(floating_base=False)
    model.add_revolute(0, [0, 1, 0], None, lk.MassProperties.solid_box(0.1, [0.1, 0.01, 0.01], center=[0.05, 0, 0]), "rod")
    sim = lk.Simulation(model, backend=backend)
    sim.q = [0.3]
    return sim


def run_with_timeout(function, seconds):
    """Runs function() in a daemon thread; (finished, exception or None)."""
    outcome = {}

    def target():
        try:
            function()
        except BaseException as error:  # noqa: BLE001 - handed back to the test
            outcome["error"] = error

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(seconds)
    return not thread.is_alive(), outcome.get("error")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("torque", [1e12, 1e308])
def test_torque_in_wrong_units_raises_naming_body_and_step_and_keeps_the_last_good_state(backend, torque):
    sim, twin = small_pendulum(backend), small_pendulum(backend)
    sim.step(n=25)
    twin.step(n=25)
    # The twin finds the failing step one step at a time; its state just before is the last good one.
    failing = None
    for k in range(1, 11):
        good = (twin.q, twin.v, twin.time)
        try:
            twin.step([torque])
        except RuntimeError:
            failing = 25 + k
            break
    assert failing is not None, (
        f"{backend}: a {torque:g} N m torque on a 3e-4 kg m^2 rod ran 10 steps without error: "
        f"q {good[0]} -> {twin.q} rad, v {good[1]} -> {twin.v} rad/s, applied tau {twin.applied_tau}"
    )
    assert failing <= 25 + 3, "the guard should trip within a few steps"
    finished, error = run_with_timeout(lambda: sim.step([torque], n=10**7), 30.0)
    assert finished, f"{backend}: step did not return"
    assert isinstance(error, RuntimeError), f"{backend}: expected RuntimeError, got {error!r}"
    message = str(error)
    assert f"step {failing} " in message and '"rod"' in message, message
    assert np.array_equal(sim.q, good[0]) and np.array_equal(sim.v, good[1]) and sim.time == good[2]
    # Still usable: a reset and sane steps give what a fresh simulation gives.
    sim.reset([0.3])
    sim.step([0.01], n=100)
    fresh = small_pendulum(backend)
    fresh.step([0.01], n=100)
    assert sim.time == pytest.approx(0.1) and np.all(np.isfinite(sim.q)) and np.all(np.isfinite(sim.v))
    assert np.array_equal(sim.q, fresh.q) and np.array_equal(sim.v, fresh.v)


# ------------------------------------------------------------------------------------------------------
# 4. SimulationBatch
# ------------------------------------------------------------------------------------------------------

BATCH_BACKENDS = ("tree", "rapier", "tree", "rapier")
BATCH_HEIGHTS = (0.36, 0.4, 0.45, 0.38)


def quadruped_on_servos(backend, height):
    model, shapes = quadruped()
    sim = lk.Simulation(model, ground=lk.Ground.plane(0.8), shapes=shapes, backend=backend)
    q = model.neutral()
    q[2] = height
    sim.q = q
    sim.set_servo(kp=40.0, kd=0.3, torque_limit=20.0, target_q=model.neutral())
    return sim


def quadruped_batch():
    return [quadruped_on_servos(b, h) for b, h in zip(BATCH_BACKENDS, BATCH_HEIGHTS)]


def state(sim):
    return sim.q, sim.v, sim.time


@pytest.mark.parametrize("form", ["none", "shared", "rows", "list"])
def test_batch_steps_are_bit_identical_to_stepping_each_simulation_alone(form):
    batched, alone = quadruped_batch(), quadruped_batch()
    batch = lk.SimulationBatch(batched)
    count, nv, nq = len(batched), batched[0].v.size, batched[0].q.size
    rng = np.random.default_rng(7)
    rows = rng.uniform(-0.5, 0.5, (count, nv))
    rows[:, :6] = 0.0
    tau, per_sim = {
        "none": (None, [None] * count),
        "shared": (rows[0], [rows[0]] * count),
        "rows": (rows, list(rows)),
        "list": ([rows[0], None, rows[2], rows[3]], [rows[0], None, rows[2], rows[3]]),
    }[form]
    batch.step(tau, n=200)
    for sim, t in zip(alone, per_sim):
        sim.step(t, n=200)
    assert len(batch) == count and batch.q.shape == (count, nq) and batch.v.shape == (count, nv)
    assert all(a is b for a, b in zip(batch.simulations, batched))
    for i, (a, b) in enumerate(zip(batched, alone)):
        assert np.array_equal(a.q, b.q) and np.array_equal(a.v, b.v) and a.time == b.time, f"simulation {i}"
        assert np.array_equal(batch.q[i], b.q) and np.array_equal(batch.v[i], b.v)
    # The members stay usable alone, and batch stepping continues from where they are.
    batched[1].step(n=3)
    alone[1].step(n=3)
    batch.step(tau, n=5)
    for sim, t in zip(alone, per_sim):
        sim.step(t, n=5)
    assert all(np.array_equal(a.q, b.q) and np.array_equal(a.v, b.v) for a, b in zip(batched, alone))


def test_batch_rejects_bad_tau_naming_it_and_moves_nothing():
    sims = quadruped_batch()
    batch = lk.SimulationBatch(sims)
    batch.step(n=10)
    count, nv = len(sims), sims[0].v.size
    before = [state(s) for s in sims]
    with_nan = np.zeros((count, nv))
    with_nan[3, 8] = np.nan
    bad = [
        np.zeros(nv + 1),
        np.zeros((count - 1, nv)),
        np.zeros((count, nv + 1)),
        np.zeros((2, count, nv)),
        with_nan,
        np.full(nv, np.inf),
        [np.zeros(nv)] * (count - 1),
        [np.zeros(nv), np.zeros(nv), np.zeros(3), None],
        [np.zeros(nv), None, None, np.full(nv, np.nan)],
    ]
    for tau in bad:
        with pytest.raises(ValueError, match="tau"):
            batch.step(tau, n=5)
    with pytest.raises(ValueError, match="n"):
        batch.step(n=-1)
    after = [state(s) for s in sims]
    for (q0, v0, t0), (q1, v1, t1) in zip(before, after):
        assert np.array_equal(q0, q1) and np.array_equal(v0, v1) and t0 == t1


def test_batch_rejects_the_same_simulation_twice_and_non_simulations():
    a, b = small_pendulum("tree"), small_pendulum("rapier")
    with pytest.raises(ValueError, match="twice"):
        lk.SimulationBatch([a, b, a])
    with pytest.raises(TypeError):
        lk.SimulationBatch([a, "not a simulation"])
    with pytest.raises(TypeError):
        lk.SimulationBatch([a, lk.Ground.plane()])
    with pytest.raises(ValueError):
        lk.SimulationBatch([])
    assert len(lk.SimulationBatch([a, b])) == 2


def steps_before_failing(sim, tau, n):
    """How many of n steps `sim` takes alone, one at a time, before a step fails (n if none does)."""
    for k in range(n):
        try:
            sim.step(tau)
        except RuntimeError:
            return k
    return n


def test_a_batch_is_per_member_a_diverging_one_stops_the_others_advance_and_each_members_steps_are_reported():
    """The policy (docs/errors.md, docstring): per member. Members 1 and 2 diverge (a 1e12 N m torque on a 3e-4 kg m^2
    rod; member 2 after 20 good steps of its own first): each stops at its last good state, bit-identical to
    stepping it alone up to its failing step; the others take all 150 steps, bit-identical to stepping alone; the
    error names index 1 and, with `steps`, what every member took."""
    backends = ("tree", "rapier", "tree", "rapier", "tree")
    sims = [small_pendulum(b) for b in backends]
    alone = [small_pendulum(b) for b in backends]
    sims[2].step([0.01], n=20)
    alone[2].step([0.01], n=20)
    taus = [np.array([0.01]), np.array([1e12]), np.array([1e12]), np.array([-0.02]), None]
    steps = 150
    expected = [steps_before_failing(twin, tau, steps) for twin, tau in zip(alone, taus)]
    assert expected[0] == expected[3] == expected[4] == steps and expected[1] < steps and expected[2] < steps, expected
    batch = lk.SimulationBatch(sims)
    finished, error = run_with_timeout(lambda: batch.step(taus, n=steps), 30.0)
    assert finished
    assert isinstance(error, RuntimeError), repr(error)
    message = str(error)
    assert message.startswith("step[1]: ") and '"rod"' in message, message
    assert message.endswith(
        f"; per member: simulations[1] after {expected[1]}, simulations[2] after {expected[2]} of {steps} steps stopped at the last "
        f"good state, the other 3 took all {steps} (steps: each member's)"
    ), message
    assert error.steps == expected
    for i, (sim, twin) in enumerate(zip(sims, alone)):
        assert sim.time == pytest.approx(twin.time) and np.array_equal(sim.q, twin.q) and np.array_equal(sim.v, twin.v), f"simulation {i}"


# ------------------------------------------------------------------------------------------------------
# 5. Determinism
# ------------------------------------------------------------------------------------------------------


def test_tree_engine_is_bit_deterministic_and_reset_reproduces_a_fresh_run():
    terrain = lk.Ground.heightfield(0.02 * np.sin(np.arange(21)[:, None] * 0.7 + np.arange(15)[None, :] * 0.4), 0.1, 0.8)

    def make():
        model, _ = quadruped()  # default boxes on every body, colliding with each other too
        sim = lk.Simulation(model, ground=terrain, self_collision=True, substeps=2, backend="tree")
        q = model.neutral()
        q[2] = 0.45
        q[7:] = [0.6, -1.2] * 4
        sim.q = q
        sim.set_servo(kp=30.0, kd=0.2, torque_limit=10.0, target_q=q)
        return sim

    def run(sim):
        nv = sim.v.size
        trajectory = []
        for k in range(20):
            tau = np.where(np.arange(nv) < 6, 0.0, 0.5 * np.sin(np.arange(nv) + 0.3 * k))
            sim.step(tau, n=30)
            trajectory.append(np.concatenate([sim.q, sim.v, sim.applied_tau, [sim.time]]))
        contacts = sim.contacts()
        return np.array(trajectory), contacts, sim.body_poses()

    first_sim = make()
    q0, v0 = first_sim.q, first_sim.v
    first, second = run(first_sim), run(make())
    assert len(first[1]["body"]) > 0, "the scene should be in contact at the end"
    assert np.array_equal(first[0], second[0]), "two runs of the same scene differ"
    assert np.array_equal(first[2], second[2])
    assert first[1].keys() == second[1].keys() and all(np.array_equal(first[1][k], second[1][k]) for k in first[1])
    # Reset after a run (contacts warm, impulses stored): the same trajectory as a fresh simulation.
    first_sim.step(n=37)
    first_sim.reset(q0, v0)
    assert first_sim.time == 0.0
    again = run(first_sim)
    assert np.array_equal(again[0], first[0])
    assert all(np.array_equal(again[1][k], first[1][k]) for k in first[1])


# ------------------------------------------------------------------------------------------------------
# 6. Self-collision switch
# ------------------------------------------------------------------------------------------------------

ARM_LENGTH, ARM_RADIUS, ARM_OFFSET = 0.3, 0.02, 0.1


def two_arms(self_collision):
    """Two capsule arms hanging from x = -0.1 ("a", held by a stiff servo) and x = +0.1 ("b", thrown toward a)."""
    model = lk.Model(floating_base=False, base=lk.MassProperties.solid_box(1.0, [0.3, 0.1, 0.05]))
    arm = lk.MassProperties.solid_box(0.5, [0.04, 0.04, ARM_LENGTH], center=[0, 0, -ARM_LENGTH / 2])
    model.add_revolute(0, [0, 1, 0], (np.eye(3), [-ARM_OFFSET, 0, 0]), arm, "a")
    model.add_revolute(0, [0, 1, 0], (np.eye(3), [ARM_OFFSET, 0, 0]), arm, "b")
    placement = np.eye(4)
    placement[2, 3] = -ARM_LENGTH / 2
    capsule = ("capsule", ARM_LENGTH / 2, ARM_RADIUS, placement)
    sim = lk.Simulation(model, shapes={0: None, "a": capsule, "b": capsule}, self_collision=self_collision, backend="tree")
    sim.set_servo(kp=[2000.0, 0.0], kd=[20.0, 0.0], target_q=[0.0, 0.0])
    # Rotating about +y takes b's tip toward -x; 12 rad/s carries it well past a (it needs ~0.73 rad).
    sim.v = [0.0, 12.0]
    return sim


def swing(sim, steps=600):
    """Smallest (tip of b - tip of a) along x over the run, and every self-contact seen."""
    gap, seen = np.inf, []
    for _ in range(steps):
        sim.step()
        poses = sim.body_poses()
        tips = [(poses[i] @ [0, 0, -ARM_LENGTH, 1])[0] for i in (1, 2)]
        gap = min(gap, tips[1] - tips[0])
        contacts = sim.contacts()
        for k in np.flatnonzero(contacts["other"] != -1):
            centres = {i: (poses[i] @ [0, 0, -ARM_LENGTH / 2, 1])[:3] for i in (1, 2)}
            body, other = int(contacts["body"][k]), int(contacts["other"][k])
            seen.append((body, other, contacts["normal"][k] @ (centres[body] - centres[other]), contacts["normal_force"][k]))
    return gap, seen


def test_self_collision_switch_makes_two_links_collide_or_pass_through():
    gap_on, seen_on = swing(two_arms(True))
    gap_off, seen_off = swing(two_arms(False))
    assert seen_off == [] and gap_off < -ARM_OFFSET / 2, f"without self-collision b should pass a: gap {gap_off}"
    assert seen_on, "with self-collision the arms should touch"
    assert {(b, o) for b, o, _, _ in seen_on} <= {(1, 2), (2, 1)}
    # Normals point into the body the force acts on, i.e. away from the other arm; the arms push apart.
    assert all(separating > 0 for _, _, separating, _ in seen_on)
    assert max(force for *_, force in seen_on) > 0
    # b never gets past a: the tips stay apart by about the two radii.
    assert gap_on > 2 * ARM_RADIUS - 2e-3, f"tips came within {gap_on} m"
