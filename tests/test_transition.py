"""`Simulation.transition_jacobians` against central differences of `Simulation.step` (each displaced step replayed
from a freshly built scene, so the contact history and warm starts are the same), against MuJoCo's
`mjd_transitionFD` on a contact-free chain (where both engines integrate the same semi-implicit Euler step), and
its refusals. The Rust tests (crates/dynamics/tests/transition.rs) cover sliding boxes, parry hulls, joint limits
and saturated servos."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import legkit as lk
from conftest import examples
from test_hostile import chain_urdf, outcome
from test_simulation import standing_quadruped, ten_link_tree

# Below the 0.5 µm a resting contact sits from where its Baumgarte law bends, and below the distance to a zone's edge
# of a lightly loaded foot sliding at the cone's edge (a few 1e-7 in q on a settling quadruped).
STEP = 1e-8


def targets_configuration(model: lk.Model, target_q: np.ndarray, per_velocity: np.ndarray) -> np.ndarray:
    """`target_q` (nq) with its one-coordinate joints' coordinates moved by `per_velocity` (nv); a ball joint takes no
    position servo, so its target is left."""
    out = target_q.copy()
    for i in range(1, model.nbodies):
        if model.joint_type(i) != "spherical":
            out[model.idx_q[i]] += per_velocity[model.idx_v[i]]
    return out


def jacobians_and_differences(build, tau: np.ndarray, servo: dict, step_size: float = STEP) -> tuple[np.ndarray, np.ndarray]:
    """[A | B] at `build()`'s state and the same by central differences of one step in each of the 5 nv inputs,
    displaced by `step_size`; `servo` holds the set_servo arguments `build` used (target_q a configuration)."""
    sim = build()
    model = sim.model
    nv = model.nv
    a, b = sim.transition_jacobians(tau)
    q, v = sim.q.copy(), sim.v.copy()

    def step(column: int, delta: float):
        displaced = build()
        d = np.zeros(5 * nv)
        d[column] = delta
        displaced.q = lk.integrate(model, q, d[:nv], 1.0)
        displaced.v = v + d[nv:2 * nv]
        displaced.set_servo(servo["kp"], servo["kd"], servo["torque_limit"],
                            targets_configuration(model, servo["target_q"], d[3 * nv:4 * nv]), d[4 * nv:])
        displaced.step(tau + d[2 * nv:3 * nv])
        return displaced.q, displaced.v

    q_next, _ = step(0, 0.0)
    numeric = np.zeros((2 * nv, 5 * nv))
    for column in range(5 * nv):
        (q_plus, v_plus), (q_minus, v_minus) = step(column, step_size), step(column, -step_size)
        numeric[:nv, column] = (lk.difference(model, q_next, q_plus) - lk.difference(model, q_next, q_minus)) / (2 * step_size)
        numeric[nv:, column] = (v_plus - v_minus) / (2 * step_size)
    return np.hstack([a, b]), numeric


def assert_close(analytic: np.ndarray, numeric: np.ndarray, tolerance: float = 1e-6) -> None:
    scale = max(1.0, np.abs(analytic).max())
    error = np.abs(analytic - numeric).max()
    row, column = np.unravel_index(np.abs(analytic - numeric).argmax(), analytic.shape)
    assert error <= tolerance * scale, f"off by {error:.2e} at ({row}, {column}): {analytic[row, column]} vs {numeric[row, column]}"


QUADRUPED_SERVO = {"kp": 40.0, "kd": 0.3, "torque_limit": 20.0}


# No push (every foot sticks) or a push that sets the feet sliding well inside their sliding zone: a small push, or
# a robot still landing, leaves feet at the edge between sticking and sliding, within 1e-8 of a switch.
pushes = st.one_of(st.just((0.0, 0.0, 0.0)), st.tuples(st.floats(0.15, 0.3), st.floats(-0.3, 0.3), st.floats(-0.1, 0.1)))


@given(push=pushes, settle=st.integers(150, 300), seed=st.integers(0, 2**16))
@examples(4)
def test_standing_and_pushed_quadruped_matches_central_differences(push, settle, seed):
    """Feet sticking (no push) or sliding (pushed), servos implicit, warm starts from `settle` steps."""
    model = standing_quadruped(lk.Ground.plane(0.8)).model
    servo = dict(QUADRUPED_SERVO, target_q=model.neutral())
    tau = np.r_[np.zeros(6), 0.3 * np.random.default_rng(seed).standard_normal(model.nv - 6)]

    def build() -> lk.Simulation:
        sim = standing_quadruped(lk.Ground.plane(0.8))
        sim.step(None, settle)
        sim.v = sim.v + np.r_[push, np.zeros(model.nv - 3)]
        return sim

    assert len(build().contacts()["body"]) > 0
    assert_close(*jacobians_and_differences(build, tau, servo))


@pytest.mark.parametrize("substeps", [2, 4])
@pytest.mark.parametrize("push", [0.0, 0.25], ids=["sticking", "sliding"])
def test_substeps_compose_to_central_differences(substeps, push):
    """A step of several substeps: each substep's Jacobians chained, its warm starts followed from the substep before
    (the friction rows ask for R_t λ_t,warm, so holding them constant would be off by about 1e-2). A resting foot
    settles within ε g h² of where its normal row's law bends, h the substep, so the displacement shrinks with h²."""
    model = standing_quadruped(lk.Ground.plane(0.8)).model
    servo = dict(QUADRUPED_SERVO, target_q=model.neutral())
    tau = np.r_[np.zeros(6), 0.3 * np.random.default_rng(substeps).standard_normal(model.nv - 6)]

    def build() -> lk.Simulation:
        sim = standing_quadruped(lk.Ground.plane(0.8), substeps=substeps, friction_law="cone" if push else "coulomb")
        sim.step(None, 200)
        sim.v = sim.v + np.r_[push, np.zeros(model.nv - 1)]
        return sim

    assert len(build().contacts()["body"]) > 0
    # 10 substeps are checked in Rust: this scene's feet rest 3.5e-9 m deep with them, where displacements small
    # enough (1e-9) magnify the solve's own convergence error (1e-10 of its impulses) to about 1e-6 of the Jacobians.
    # Pushed, the cone law: under Coulomb's that error swamps these displacements already (the mismatch grows as
    # 1 / displacement: 1e-6, 1e-5, 7e-5 at 1e-7, 1e-8, 1e-9 over 16); Rust checks Coulomb's law with 4 and 10 substeps.
    assert_close(*jacobians_and_differences(build, tau, servo, STEP / substeps**2))


BOX = np.array([0.3, 0.2, 0.1])
BOX_TAU = np.array([0.0, 0.0, 0.0, 0.05, -0.02, 0.01])


def sliding_box(substeps: int, friction_law: str, settle: int) -> lk.Simulation:
    """A 2 kg box set down flat 10 µm above the plane, sliding at (0.8, 0.3) m/s and turning at 0.2 rad/s, run
    `settle` steps."""
    sim = lk.Simulation(lk.Model(True, lk.MassProperties.solid_box(2.0, BOX)), dt=1e-3, ground=lk.Ground.plane(0.8),
                        substeps=substeps, friction_law=friction_law)
    sim.q = np.array([0.0, 0.0, BOX[2] / 2 + 1e-5, 0.0, 0.0, 0.0, 1.0])
    sim.v = np.array([0.8, 0.3, 0.0, 0.0, 0.0, 0.2])
    sim.step(BOX_TAU, settle)
    return sim


def one_sided_slopes(build, tau: np.ndarray, step_size: float) -> tuple[np.ndarray, np.ndarray]:
    """The slopes of one step on each side of every input of x = (q on its tangent space, v), Richardson-extrapolated
    from displacements of `step_size` and twice it: (right, left), each 2 nv x 2 nv."""
    sim = build()
    model, nv = sim.model, sim.model.nv
    q, v = sim.q.copy(), sim.v.copy()

    def step(column: int, delta: float) -> np.ndarray:
        displaced = build()
        d = np.zeros(2 * nv)
        d[column] = delta
        displaced.q, displaced.v = lk.integrate(model, q, d[:nv], 1.0), v + d[nv:]
        displaced.step(tau)
        return np.concatenate([lk.difference(model, q_next, displaced.q), displaced.v])

    undisplaced = build()
    undisplaced.step(tau)
    q_next = undisplaced.q.copy()
    base = step(0, 0.0)
    sides = []
    for sign in (1.0, -1.0):
        slopes = np.zeros((2 * nv, 2 * nv))
        for column in range(2 * nv):
            near = (step(column, sign * step_size) - base) / (sign * step_size)
            far = (step(column, 2 * sign * step_size) - base) / (2 * sign * step_size)
            slopes[:, column] = 2 * near - far
        sides.append(slopes)
    return sides[0], sides[1]


@pytest.mark.parametrize("substeps", [2, 10])
def test_a_box_sliding_in_substeps_has_the_slopes_of_the_side_its_step_is_on(substeps):
    """Under Coulomb's law a sliding box rests on its contacts' gap-0 bend (within ε g h² of it, 7e-9 m with 10
    substeps), and tilting it by 1e-7 rad lifts an edge past it: central differences of its height and tilt
    straddle a switch (6e-5 off with 10 substeps). The Jacobians hold the step's side: each of their columns equals
    the one-sided slopes of the step on one side, displaced by 1e-8 (the step's solve converged to about 1e-12
    leaves 1e-4 of noise in slopes at 1e-9)."""
    build = lambda: sliding_box(substeps, "coulomb", 20)  # noqa: E731
    sim = build()
    assert len(sim.contacts()["body"]) == 4
    a, _ = sim.transition_jacobians(BOX_TAU)
    right, left = one_sided_slopes(build, BOX_TAU, 1e-8)
    scale = max(1.0, np.abs(a).max())
    per_column = np.minimum(np.abs(a - right).max(axis=0), np.abs(a - left).max(axis=0))
    assert per_column.max() <= 1e-6 * scale, f"columns off both sides' slopes by {per_column.max() / scale:.1e} (relative)"


def test_servoed_tree_without_contacts_matches_central_differences():
    model = ten_link_tree()
    target = model.neutral() + 0.2
    servo = {"kp": 30.0, "kd": 0.5, "torque_limit": 1.5, "target_q": target}  # a few servos saturate

    def build() -> lk.Simulation:
        sim = lk.Simulation(model, dt=1e-3)
        sim.set_servo(servo["kp"], servo["kd"], servo["torque_limit"], target)
        sim.step(None, 120)
        return sim

    assert_close(*jacobians_and_differences(build, np.linspace(-0.2, 0.2, model.nv), servo))


CHAIN_URDF = """<robot name="chain">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  {links}
</robot>"""
LINK = """<link name="l{k}"><inertial><origin xyz="0.15 0 0.02"/><mass value="{mass}"/>
    <inertia ixx="0.002" iyy="0.01" izz="0.011" ixy="0.001" ixz="0" iyz="0"/></inertial></link>
  <joint name="j{k}" type="revolute"><parent link="{parent}"/><child link="l{k}"/><origin xyz="{x} 0 0" rpy="0.3 0 0.2"/>
    <axis xyz="{axis}"/><limit lower="-10" upper="10" effort="100" velocity="100"/></joint>"""


def test_contact_free_chain_matches_mujoco():
    """Without contacts, servos or damping both engines take v⁺ = v + h M⁻¹ (τ − c), q⁺ = q + h v⁺, so A and
    B (torque columns) agree to MuJoCo's centred finite differences."""
    mujoco = pytest.importorskip("mujoco")
    axes = ["0 1 0", "0 0.6 0.8", "1 0 0", "0 1 0"]
    links = "\n  ".join(
        LINK.format(k=k, mass=1.0 - 0.2 * k, parent="base" if k == 0 else f"l{k - 1}", x=0.0 if k == 0 else 0.3, axis=axis)
        for k, axis in enumerate(axes)
    )
    urdf = CHAIN_URDF.format(links=links)
    model = lk.Model.from_urdf(urdf)
    sim = lk.Simulation(model, dt=1e-3)
    q, v, tau = np.array([0.3, -0.5, 0.8, 0.2]), np.array([1.0, -2.0, 0.5, 3.0]), np.array([0.5, -0.2, 0.1, 0.3])
    sim.q, sim.v = q, v
    a, b = sim.transition_jacobians(tau)

    m = mujoco.MjModel.from_xml_string(urdf)
    m.opt.timestep = 1e-3
    m.opt.gravity[:] = [0, 0, -lk.STANDARD_GRAVITY]
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:], d.qfrc_applied[:] = q, v, tau
    mujoco.mj_forward(m, d)
    a_mj = np.zeros((2 * m.nv, 2 * m.nv))
    mujoco.mjd_transitionFD(m, d, 1e-6, True, a_mj, None, None, None)
    assert_close(a, a_mj, 1e-7)
    # B by torques: MuJoCo's applied generalized forces enter as tau does; by centred differences of mj_step.
    numeric = np.zeros((2 * m.nv, m.nv))
    for k in range(m.nv):
        states = []
        for sign in (1, -1):
            d.qpos[:], d.qvel[:], d.qfrc_applied[:] = q, v, tau
            d.qfrc_applied[k] += sign * 1e-6
            mujoco.mj_step(m, d)
            states.append(np.r_[d.qpos, d.qvel])
        numeric[:, k] = (states[0] - states[1]) / 2e-6
    assert_close(b[:, : m.nv], numeric, 1e-7)


def test_asking_changes_nothing():
    def build() -> lk.Simulation:
        sim = standing_quadruped(lk.Ground.plane(0.8))
        sim.step(None, 200)
        return sim

    asked, twin = build(), build()
    asked.transition_jacobians(np.ones(asked.model.nv))
    for sim in (asked, twin):
        sim.step(None, 100)
    assert np.array_equal(asked.q, twin.q) and np.array_equal(asked.v, twin.v) and asked.time == twin.time
    for key, value in asked.contacts().items():
        assert np.array_equal(value, twin.contacts()[key]), key


def test_refusals_name_the_argument():
    model = ten_link_tree()
    with pytest.raises(ValueError, match="backend"):
        lk.Simulation(model, backend="rapier").transition_jacobians()
    with pytest.raises(ValueError, match="tau"):
        lk.Simulation(model).transition_jacobians(np.zeros(model.nv + 1))


def test_a_batch_gives_each_simulations_jacobians():
    def pushed(push: float) -> lk.Simulation:
        sim = standing_quadruped(lk.Ground.plane(0.8))
        sim.step(None, 200)
        sim.v = sim.v + np.r_[push, np.zeros(sim.model.nv - 1)]
        return sim

    sims = [pushed(p) for p in (0.0, 0.2, 0.25)]
    tau = np.stack([np.r_[np.zeros(6), np.full(8, 0.1 * k)] for k in range(3)])
    a, b = lk.SimulationBatch(sims).transition_jacobians(tau)
    assert a.shape == (3, 28, 28) and b.shape == (3, 28, 42)
    for k, sim in enumerate(sims):
        a_k, b_k = sim.transition_jacobians(tau[k])
        assert np.array_equal(a[k], a_k) and np.array_equal(b[k], b_k)
    with pytest.raises(ValueError, match="nv"):
        lk.SimulationBatch([sims[0], lk.Simulation(ten_link_tree())]).transition_jacobians()


def test_a_model_too_large_for_the_jacobians_buffers_is_a_memory_error(tmp_path):
    """The Jacobians of a step of two substeps on a 1,000-joint chain hold about 40 nv² numbers (320 MB): under a
    limit of 25 nv² past the probe for 20 nv² (`Simulation::transition_jacobians`), the buffers behind them are
    allocated fallibly, a MemoryError naming the model, the simulation as it was; not an abort."""
    (tmp_path / "chain.urdf").write_text(chain_urdf(1001))
    result = outcome(
        f"""
model = lk.Model.from_urdf({str(tmp_path / "chain.urdf")!r})
sim = lk.Simulation(model, substeps=2)
sim.step(None, 2)
before = (sim.q.copy(), sim.v.copy(), sim.time)
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 25 * 8 * model.nv**2, vm + 25 * 8 * model.nv**2))
try:
    sim.transition_jacobians()
except MemoryError as error:
    same = bool((sim.q == before[0]).all() and (sim.v == before[1]).all() and sim.time == before[2])
    report(raised="MemoryError", message=str(error), same=same)
""",
        memory=0,
        timeout=120,
    )
    assert result["raised"] == "MemoryError" and "model" in result["message"] and "bytes" in result["message"], result
    assert result["same"], result


@pytest.mark.parametrize("substeps", [1, 2, 4, 10])
def test_a_servoed_tree_in_substeps_matches_central_differences(substeps):
    """The chain through the substeps (each substep's slopes applied to the running Jacobian, `transition.rs`) without
    contacts: the servos' implicit terms, saturation and the integration carried through every substep."""
    model = ten_link_tree()
    target = model.neutral() + 0.2
    servo = {"kp": 30.0, "kd": 0.5, "torque_limit": 1.5, "target_q": target}

    def build() -> lk.Simulation:
        sim = lk.Simulation(model, dt=1e-3, substeps=substeps)
        sim.set_servo(servo["kp"], servo["kd"], servo["torque_limit"], target)
        sim.step(None, 120)
        return sim

    assert_close(*jacobians_and_differences(build, np.linspace(-0.2, 0.2, model.nv), servo))


@pytest.mark.parametrize("substeps", [1, 2, 4])
def test_a_box_resting_in_substeps_matches_central_differences(substeps):
    """Four sticking contacts whose warm starts pass from substep to substep (the friction rows ask for R_t λ_t,warm):
    each contact's slopes by its own warm start act along its chain, no dense product over all contacts. A resting
    corner settles within ε g h² of its normal law's bend, h the substep: the displacement shrinks with h². With 10
    substeps no displacement is clean (1e-8 straddles the bend, 1e-9 and 1e-10 leave 1e-5 and 3e-5 of the solve's
    noise); the Rust tests check 10 substeps on the quadruped, and the servoed tree above has no bend."""

    def build() -> lk.Simulation:
        sim = sliding_box(substeps, "cone", 0)
        sim.v = np.zeros(6)
        sim.step(BOX_TAU, 60)
        return sim

    assert len(build().contacts()["body"]) == 4
    servo = {"kp": 0.0, "kd": 0.0, "torque_limit": 1.0, "target_q": build().model.neutral()}
    assert_close(*jacobians_and_differences(build, BOX_TAU, servo, STEP / substeps**2))
