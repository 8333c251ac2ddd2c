"""Ball joints in the tree engine: a rod hanging on a ball joint against closed forms, a ball-jointed MJCF model against
MuJoCo's `mj_step`, and the policy for servos on ball joints.

The rod: mass m, length L along its body's -z axis from the joint, a square cross-section; its COM at depth d = L/2,
its inertia about the joint A across the rod and C along it. Closed forms of the heavy symmetric top hanging down:
- small swings have the period 2 pi sqrt(A / (m g d)) (1 + theta0^2 / 16 + ...);
- a steady conical motion, the rod turning rigidly about the vertical at tilt theta, needs
  Omega^2 = m g d / ((A - C) cos theta) (gravity's torque m g d sin theta equals d(L)/dt = Omega x L);
- the spin about the rod's axis and the angular momentum about the vertical are conserved, whatever the motion.
"""

from __future__ import annotations

import numpy as np
import pytest

import legkit as lk
from test_ball_joints import quaternion, rotation

MASS, LENGTH, WIDTH = 1.0, 0.5, 0.04
G = lk.STANDARD_GRAVITY


def rod() -> lk.MassProperties:
    return lk.MassProperties.solid_box(MASS, [WIDTH, WIDTH, LENGTH], center=[0.0, 0.0, -LENGTH / 2])


def pendulum() -> lk.Model:
    model = lk.Model(floating_base=False)
    model.add_spherical(0, None, rod(), "rod")
    return model


def inertias() -> tuple[float, float]:
    """A (across the rod) and C (along it) about the joint."""
    about = rod().inertia_about([0.0, 0.0, 0.0])
    return float(about[0, 0]), float(about[2, 2])


def axis_of(q: np.ndarray) -> np.ndarray:
    """The rod's axis (body -z) in the world."""
    x, y, z, w = q
    return -np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])


def energy(model: lk.Model, q: np.ndarray, v: np.ndarray) -> float:
    return float(lk.kinetic_energy(model, q, v) + lk.potential_energy(model, q))


def run(q0: np.ndarray, v0: np.ndarray, dt: float, seconds: float):
    """Yields (q, v) after each step."""
    model = pendulum()
    sim = lk.Simulation(model, dt=dt)
    sim.q, sim.v = q0, v0
    for _ in range(round(seconds / dt)):
        sim.step()
        yield sim.q, sim.v


def test_small_swings_have_the_closed_form_period() -> None:
    # Released from 0.05 rad about x. Tolerance: the amplitude's next term theta0^4 11/3072 is 2e-8, semi-implicit
    # Euler's frequency error (omega h)^2 / 24 is 1e-8 at h = 0.1 ms, the crossings' linear interpolation O(h^2)
    # per crossing: 1e-5 relative bounds all of them with room; the amplitude term alone (1.6e-4) is 16 times that.
    a, _ = inertias()
    theta0, dt = 0.05, 1e-4
    period = 2 * np.pi * np.sqrt(a / (MASS * G * LENGTH / 2)) * (1 + theta0**2 / 16)
    tilt = np.array([axis_of(q)[1] for q, _ in run(quaternion([1, 0, 0], theta0), np.zeros(3), dt, 3.2 * period)])
    t = np.arange(1, len(tilt) + 1) * dt
    up = np.flatnonzero((tilt[:-1] < 0) & (tilt[1:] >= 0))
    crossings = t[up] + dt * -tilt[up] / (tilt[up + 1] - tilt[up])
    measured = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    assert len(crossings) >= 3
    assert abs(measured / period - 1) < 1e-5, f"period {measured:.6f} s, closed form {period:.6f} s"


def vertical_momentum(q: np.ndarray, v: np.ndarray) -> float:
    a, c = inertias()
    return float((rotation(q) @ np.diag([a, a, c]) @ v)[2])


def test_spin_and_vertical_momentum_are_conserved() -> None:
    # Released from 0.8 rad swinging across: gravity has no torque about the vertical or about the symmetric rod's
    # axis, so both momenta are constant along the exact motion. Without spin the gyroscopic term w x (I w) vanishes
    # (w across the axis, I = diag(A, A, C)) and each step conserves both to rounding; spinning at 20 rad/s the spin
    # still is (the body-frame update of its axial component is exact), while semi-implicit Euler's explicit
    # gyroscopic term moves the vertical momentum by O(h): halving h halves its largest deviation over 2 s.
    q0 = quaternion([1, 0, 0], 0.8)
    still = np.array([0.0, 2.0, 0.0])
    start = vertical_momentum(q0, still)
    for q, v in run(q0, still, 1e-3, 2.0):
        assert abs(v[2]) < 1e-12 and abs(vertical_momentum(q, v) - start) < 1e-12
    spinning = np.array([0.0, 2.0, 20.0])
    start = vertical_momentum(q0, spinning)
    deviations = []
    for dt in (2e-3, 1e-3, 5e-4):
        deviation = 0.0
        for q, v in run(q0, spinning, dt, 2.0):
            assert abs(v[2] - 20.0) < 1e-11
            deviation = max(deviation, abs(vertical_momentum(q, v) - start))
        deviations.append(deviation)
    for coarse, fine in zip(deviations, deviations[1:]):
        assert 1.6 < coarse / fine < 2.5, f"vertical momentum deviations {deviations}"


@pytest.mark.parametrize("spin", [0.0, 20.0])
def test_energy_drift_is_first_order_in_dt(spin: float) -> None:
    # Semi-implicit Euler is first order: halving h halves the energy's largest deviation over 2 s from its start.
    q0, v0 = quaternion([1, 1, 0], 0.6), np.array([0.0, 1.5, spin])
    model = pendulum()
    start = energy(model, q0, v0)
    drifts = [max(abs(energy(model, q, v) - start) for q, v in run(q0, v0, dt, 2.0)) for dt in (1e-3, 5e-4, 2.5e-4)]
    for coarse, fine in zip(drifts, drifts[1:]):
        assert 1.6 < coarse / fine < 2.5, f"energy deviations {drifts} J"


def test_a_conical_pendulum_turns_at_the_closed_form_rate() -> None:
    # Started on the steady conical motion at 0.5 rad: the rod keeps its tilt and turns at Omega. The scheme keeps
    # this motion exactly (its body-frame velocity is constant, each step turns the rod by exp(h w) about the
    # vertical), so to rounding. Started 2 % faster, the rod swings out by more than 5e-3 rad: the test can tell.
    a, c = inertias()
    theta = 0.5
    rate = np.sqrt(MASS * G * LENGTH / 2 / ((a - c) * np.cos(theta)))
    q0 = quaternion([0, 1, 0], theta)
    for factor, steady in [(1.0, True), (1.02, False)]:
        v0 = rotation(q0).T @ np.array([0.0, 0.0, factor * rate])
        seconds = 2.0
        axes = np.array([axis_of(q) for q, _ in run(q0, v0, 1e-3, seconds)])
        tilt = np.arccos(-axes[:, 2])
        azimuth = np.unwrap(np.arctan2(axes[:, 1], axes[:, 0]))
        if steady:
            assert np.abs(tilt - theta).max() < 1e-12
            measured = (azimuth[-1] - azimuth[0]) / (seconds - 1e-3)
            assert abs(measured / rate - 1) < 1e-12, f"turns at {measured:.5f} rad/s, closed form {rate:.5f} rad/s"
        else:
            assert np.abs(tilt - theta).max() > 5e-3


def test_a_position_servo_on_a_ball_joint_is_refused_naming_its_body() -> None:
    sim = lk.Simulation(pendulum())
    with pytest.raises(ValueError, match=r"kp: .*ball joint of body 'rod'"):
        sim.set_servo(kp=[1.0, 0.0, 0.0])
    # A velocity servo acts per axis of the body's angular velocity.
    sim.v = [1.0, -2.0, 3.0]
    sim.set_servo(np.zeros(3), kd=[50.0, 50.0, 50.0])
    sim.step(n=50)
    assert np.abs(sim.v).max() < 0.05


def leaning_rod(settle: int) -> lk.Simulation:
    """The rod's pivot 0.2 m above the plane (mu 0.8), the rod leaning out until its axis meets the ground, turned about
    the vertical at 2 rad/s (its end sliding round the pivot) and spinning about its axis; `settle` steps run."""
    model = lk.Model(floating_base=False)
    model.add_spherical(0, (np.eye(3), [0.0, 0.0, 0.2]), rod(), "rod")
    sim = lk.Simulation(model, dt=1e-3, ground=lk.Ground.plane(0.8))
    sim.q = quaternion([1.0, 0.0, 0.0], np.arccos(0.2 / LENGTH))
    sim.v = rotation(sim.q).T @ np.array([0.0, 0.0, 2.0]) + np.array([0.0, 0.0, 1.5])
    sim.step(n=settle)
    return sim


@pytest.mark.parametrize("settle", [5, 20])
def test_transition_jacobians_of_a_ball_joint_match_central_differences(settle: int) -> None:
    """The sliding end's contact rows move with the ball joint's three columns of the factor; A and B against central
    differences of the step (q displaced on its tangent space by `lk.integrate`), as `test_transition` checks the
    one-coordinate joints. A velocity servo acts (kd per axis); a position servo is refused on a ball joint."""
    from test_transition import assert_close, jacobians_and_differences

    assert len(leaning_rod(settle).contacts()["body"]) > 0
    servo = {"kp": 0.0, "kd": 0.05, "torque_limit": 10.0, "target_q": pendulum().neutral()}

    def build() -> lk.Simulation:
        sim = leaning_rod(settle)
        sim.set_servo(servo["kp"], servo["kd"], servo["torque_limit"], servo["target_q"])
        return sim

    assert_close(*jacobians_and_differences(build, np.array([0.01, -0.02, 0.03]), servo))


# A chain of two ball joints and a hinge, damped and with armature, with the integrator matched (semi-implicit Euler,
# damping implicit in both) and no contacts: both engines apply the same update to every coordinate (a ball joint's
# quaternion by exp of h times its body-frame angular velocity in both), so the trajectories agree to rounding.
CHAIN = """
<mujoco>
  <option timestep="0.002" integrator="Euler"><flag contact="disable"/></option>
  <worldbody>
    <body name="a" pos="0 0 1">
      <joint name="a" type="ball" damping="0.05" armature="0.01"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 -0.1" size="0.04"/>
      <body name="b" pos="0.3 0 -0.1" euler="10 20 30">
        <joint name="b" type="ball" damping="0.02"/>
        <geom type="box" size="0.15 0.03 0.02" pos="0.15 0 0"/>
        <body name="c" pos="0.3 0 0">
          <joint name="c" type="hinge" axis="0 1 0.3" damping="0.01"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_a_ball_jointed_chain_follows_mujoco() -> None:
    mujoco = pytest.importorskip("mujoco")
    from mjcf_compare import joint_ids, mapped

    m = mujoco.MjModel.from_xml_string(CHAIN)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(3)
    for j in (0, 1):
        quat = rng.normal(size=4)
        d.qpos[m.jnt_qposadr[j] : m.jnt_qposadr[j] + 4] = quat / np.linalg.norm(quat)
    d.qvel[:] = rng.normal(scale=2.0, size=m.nv)
    mujoco.mj_forward(m, d)
    loaded = lk.load_mjcf(CHAIN)
    ids = joint_ids(m, loaded)
    sim = lk.Simulation(loaded.model, dt=m.opt.timestep)
    sim.q, sim.v = mapped(m, d, loaded, ids)[:2]
    steps = round(0.5 / m.opt.timestep)
    mujoco.mj_step(m, d, steps)
    sim.step(None, steps)
    q, v = mapped(m, d, loaded, ids)[:2]
    # A quaternion and its negative are one rotation: compare each ball's up to sign.
    for joint in loaded.joints:
        if joint["type"] == "ball":
            at = slice(joint["idx_q"], joint["idx_q"] + 4)
            q[at] *= np.sign(q[at] @ sim.q[at])
    assert np.abs(sim.q - q).max() < 1e-9 and np.abs(sim.v - v).max() < 1e-8 * (1 + np.abs(v).max())
