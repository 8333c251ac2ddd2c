"""The closed loop of the balance controller [Moll 2006, Sect. V]: SuperBot trees whose modules'
agents (``legkit.agents``) learn their mass properties and whose joints steer the centre of mass toward the
support line (``BalanceController``), each joint's torque driving a plant for one step of ``dt``.

``run_balance`` runs trees under gain schedules (every tree under every scheme, or the runs given as ``RunSpec``)
and returns one ``RunResult`` per run: the COM's horizontal distance from the support line (the vertical
through the root's footprint) in module widths, sampled, with the summary figures (final distance, time to
10 %, overshoot, messages per module per second, energy) and the joint angles for animations. The plant is
``lk.Simulation`` on a ground plane (legkit's tree engine, or Rapier) with the joints driven through geared
servos (the model's armature and damping), all runs stepped together by ``lk.SimulationBatch``, or a
``FreePlant`` (the same fixed-base model without contacts). Branches that hang off the root's lower block lie
on the ground at zero angles, where the random start angles would sink them into it: the simulated plants are
first servoed there from zero angles (``pose_on_ground``), so every run starts at rest and out of the ground.

``legkit balance`` (``legkit.experiments.balance``) and the sweeps (``legkit.sweeps``) run it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

import legkit as lk
from legkit._extras import progress as progress_bar
from legkit._validation import check_allocation, float_array, instance, integer, is_integer, positive_scalar
from legkit.agents import AgentNetwork, BusConfig, GroundContact
from legkit.control.balance import BalanceController, BalanceKernel
from legkit.control.gains import SCHEMES, GainSchedule
from legkit.robots.superbot import ModuleTree


class Plant(Protocol):
    """What the closed loop needs from a simulator: joint torques in, joint state out (legkit's order)."""

    @property
    def q(self) -> np.ndarray: ...

    @property
    def v(self) -> np.ndarray: ...

    def step(self, tau: np.ndarray) -> None: ...


class FreePlant:
    """A fixed-base legkit model without contacts, driven through its joints' servos, stepped by semi-implicit
    Euler: ``a = lk.aba(model, q, v, tau - damping v)`` (ABA with the model's armature, ``Model.armature``,
    and its damping, ``Model.damping``: for SuperBot trees the geared servos of ``legkit.robots.superbot``);
    then ``v += dt a`` and ``q += dt v``."""

    def __init__(self, model: lk.Model, q0: np.ndarray | None = None, v0: np.ndarray | None = None, dt: float = 1e-3):
        instance(model, lk.Model, "model")
        if model.floating_base:
            raise ValueError("model: FreePlant integrates fixed-base models only")
        self.model = model
        self.dt = positive_scalar(dt, "dt")
        self._damping = model.damping
        # Copies: the plant owns its state.
        self._q = float_array(model.neutral() if q0 is None else q0, "q0", shape=(model.nq,)).copy()
        self._v = float_array(np.zeros(model.nv) if v0 is None else v0, "v0", shape=(model.nv,)).copy()

    @property
    def q(self) -> np.ndarray:
        """Joint angles (nq,) rad (a copy)."""
        return self._q.copy()

    @property
    def v(self) -> np.ndarray:
        """Joint velocities (nv,) rad/s (a copy)."""
        return self._v.copy()

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Joint accelerations (nv,) rad/s^2 of the servo-driven model."""
        return lk.aba(self.model, q, v, tau - self._damping * v)

    def step(self, tau: np.ndarray) -> None:
        """Advance one step of ``dt`` under joint torques ``tau`` (nv,) N m; raises ValueError on bad input, and
        RuntimeError if the state would stop being finite (the state is then left unchanged)."""
        tau = float_array(tau, "tau", shape=(self.model.nv,))
        v = self._v + self.dt * self.acceleration(self._q, self._v, tau)
        q = self._q + self.dt * v
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise RuntimeError("step: the state would stop being finite; the plant state is unchanged")
        self._q, self._v = q, v


PLANTS = ("tree", "rapier", "free")


DEFAULT_FRICTION = 0.8


def make_plant(
    kind: str, model: lk.Model, q0: np.ndarray, dt: float, friction: float = DEFAULT_FRICTION, ground: lk.Ground | None = None,
) -> Plant:
    """A plant of ``kind`` (one of ``PLANTS``) for ``model``, starting at rest at ``q0``: "tree" and "rapier"
    are ``lk.Simulation`` on that backend, on ``ground`` (default: a plane with Coulomb coefficient
    ``friction``); "free" a ``FreePlant`` (no ground)."""
    if kind == "free":
        return FreePlant(model, q0=q0, dt=dt)
    if kind in ("tree", "rapier"):
        # The servos (armature and damping) are the model's, as for the free plant.
        simulation = lk.Simulation(
            model, dt=dt, ground=lk.Ground.plane(friction=friction) if ground is None else ground,
            backend="tree" if kind == "tree" else "rapier",
        )
        simulation.reset(q0, None)
        return simulation
    raise ValueError(f"plant: must be one of {PLANTS}, got {kind!r}")


@dataclass(frozen=True)
class RunSpec:
    """One run of ``run_balance`` when its runs are given explicitly: tree ``tree`` (an index into its
    ``trees``) under the gain ``schedule``, starting from ``initial_angles(trees[tree], start_seed)``
    (None: ``seed + tree``, as the default runs), on ``ground`` (None: a plane with ``run_balance``'s
    ``friction``), its agents sensing every joint angle with independent Gaussian noise of standard
    deviation ``noise`` (rad) drawn from a generator seeded with ``noise_seed`` (its own, so a run's noise
    does not depend on the other runs of the call). On an asynchronous bus the run's agents draw their
    message losses, duplicates, delays and delivery order from generators of the run's own, seeded with
    ``bus_seed`` (None: the run's start seed) and the bus's seed (``BusConfig.streams``), so these do not
    depend on the other runs of the call either."""

    tree: int
    schedule: GainSchedule
    start_seed: int | None = None
    ground: lk.Ground | None = None
    noise: float = 0.0
    noise_seed: int = 0
    bus_seed: int | None = None


class _SensorNoise:
    """Each noisy run's angle noise, drawn ``NOISE_CHUNK`` control steps at a time from the run's own generator."""

    def __init__(self, runs: Sequence[RunSpec], module_slices: Sequence[slice], n_modules: int):
        self.noisy = [(i, r, module_slices[i], np.random.default_rng([r.noise_seed, 2])) for i, r in enumerate(runs) if r.noise > 0]
        self.n_modules = n_modules
        self.step = NOISE_CHUNK

    def __call__(self, angles: np.ndarray) -> np.ndarray:
        if not self.noisy:
            return angles
        if self.step == NOISE_CHUNK:  # one draw per run every NOISE_CHUNK steps, not one per run per step
            self.chunk = np.zeros((NOISE_CHUNK, self.n_modules, 3))
            for _, run, modules, rng in self.noisy:
                self.chunk[:, modules] = rng.normal(0.0, run.noise, size=(NOISE_CHUNK, modules.stop - modules.start, 3))
            self.step = 0
        self.step += 1
        return angles + self.chunk[self.step - 1]


@dataclass
class RunResult:
    """One tree x scheme run: ``times`` (s) and ``distance`` (module widths) sampled, plus the summary figures."""

    tree: int
    scheme: str
    times: np.ndarray
    distance: np.ndarray
    signed_offset: np.ndarray
    messages_per_module_second: float
    q: np.ndarray | None = None  # joint angles (samples, nq) at ``times``, for animations
    energy: float = float("nan")  # J: the integral of sum_j |tau_j v_j| over the run (see ``run_balance``)
    schedule: GainSchedule | None = None  # the run's gain schedule (scheme, c0, c1, base gains)

    @property
    def initial(self) -> float:
        return float(self.distance[0])

    @property
    def final(self) -> float:
        return float(self.distance[-1])

    @property
    def time_to_10_percent(self) -> float:
        """First time (s) the distance is at most 10 % of the initial one; NaN if never."""
        reached = np.flatnonzero(self.distance <= 0.1 * self.initial)
        return float(self.times[reached[0]]) if reached.size else float("nan")

    @property
    def overshoot(self) -> float:
        """How far the COM went past the support line along the initial offset, as a fraction of the initial distance."""
        return float(max(0.0, -self.signed_offset.min()) / self.initial) if self.initial > 0 else 0.0


def pose_on_ground(batch: lk.SimulationBatch, models: Sequence[lk.Model]) -> None:
    """Brings every simulation of ``batch`` to its start angles without going through the ground.

    The random start angles (``initial_angles``) would put modules that lie on the ground at zero angles
    (branches off the root's lower block) deep inside it. So each robot starts at zero angles, where it
    only touches the ground, and stiff servos (``POSE_KP``, ``POSE_KD``) take every joint toward its start
    angle for ``POSE_DURATION`` s; a joint whose module the ground holds back stops there. The robot
    is then released at rest from wherever it got to."""
    instance(batch, lk.SimulationBatch, "batch")
    if isinstance(models, lk.Model) or not isinstance(models, Sequence) or len(models) != len(batch.simulations):
        raise ValueError(f"models must be one Model per simulation of batch ({len(batch.simulations)})")
    for k, (simulation, model) in enumerate(zip(batch.simulations, models)):
        instance(model, lk.Model, f"models[{k}]")
        if model.nq != simulation.model.nq:
            raise ValueError(f"models[{k}]: has nq {model.nq}, its simulation {simulation.model.nq}")
    for simulation, model in zip(batch.simulations, models):
        start = simulation.q
        simulation.reset(np.zeros(model.nq), None)
        simulation.set_servo(kp=POSE_KP, kd=POSE_KD, target_q=start)
    batch.step(None, n=int(round(POSE_DURATION / batch.simulations[0].dt)))
    for simulation in batch.simulations:
        simulation.set_servo(kp=0.0)
        simulation.reset(simulation.q, None)


def initial_angles(tree: ModuleTree, seed: int) -> np.ndarray:
    """The start configuration of a run, (N, 3) rad: every joint at a random angle, uniform within
    +-INITIAL_SPREAD of the joint limit (generator seeded with ``seed``), except the root, which leans with
    both pitch joints at INITIAL_LEAN of the limit, to whichever side puts the COM farther from the support
    line (the vertical through the root), so every run starts clearly off balance."""
    instance(tree, ModuleTree, "tree")
    if integer(seed, "seed") < 0:
        raise ValueError(f"seed: must be >= 0, got {seed}")
    rng = np.random.default_rng([seed, 1])
    limit = tree.parameters.joint_limit
    angles = rng.uniform(-INITIAL_SPREAD * limit, INITIAL_SPREAD * limit, size=(tree.n_modules, 3))
    model, layout = tree.to_model()
    candidates = []
    for side in (1.0, -1.0):
        angles[0] = [side * INITIAL_LEAN * limit, 0.0, side * INITIAL_LEAN * limit]
        q = np.zeros(model.nq)
        q[layout.joint_q] = angles
        candidates.append((float(np.hypot(*lk.center_of_mass(model, q)[:2])), side))
    side = max(candidates)[1]
    angles[0] = [side * INITIAL_LEAN * limit, 0.0, side * INITIAL_LEAN * limit]
    return angles


def run_balance(
    trees: Sequence[ModuleTree], duration: float, dt: float = 1e-3, loss: float = 0.0, plant: str = "tree",
    seed: int = 0, sample_every: int = 10, progress: bool = False, rounds_per_step: int = 1,
    friction: float = DEFAULT_FRICTION, runs: Sequence[RunSpec] | None = None, bus: BusConfig | None = None,
) -> list[RunResult]:
    """Simulate every tree under every scheme for ``duration`` s (see the module docstring), or the given ``runs``.

    By default the runs are every tree under every scheme with the paper's gains (``GainSchedule.paper``),
    tree i starting from ``initial_angles(tree, seed + i)`` at rest on a plane. ``runs`` (a sequence of
    ``RunSpec``) sets each run's tree, gain schedule, start, ground and sensor noise instead. ``loss`` > 0
    runs the agents on the asynchronous bus (one-tick delays, that loss probability, acknowledgements and
    retransmission), seeded with ``seed``; ``bus`` (a ``BusConfig``, without ``streams``) sets the bus
    outright instead. The runs share one bus but not its randomness: on an asynchronous bus each run draws
    from generators of its own (``RunSpec.bus_seed``), so a run's result does not depend on the other runs
    of the call, on any bus. The agents run ``rounds_per_step`` rounds of messages per control step. One
    plant per run; the agents of all runs share one vectorised network (the runs are not connected, so they
    do not interact). Samples every
    ``sample_every`` steps; ``progress`` shows a progress bar (tqdm, from the ``plot`` extra). Every joint's torque is clipped to its servo's limit
    (``ModuleParameters.servo_torque_limit``). Each run's ``energy`` is the integral over the run of sum_j |tau_j v_j|, the
    power of every joint's applied torque (``Simulation.applied_tau``; the commanded torque for other
    plants) at the velocity it reached in that step, in J."""
    if isinstance(trees, ModuleTree) or not isinstance(trees, Sequence):
        raise TypeError(f"trees must be a sequence of ModuleTree, got {type(trees).__name__}")
    if not trees:
        raise ValueError("trees: need at least one tree")
    for k, tree in enumerate(trees):
        instance(tree, ModuleTree, f"trees[{k}]")
    positive_scalar(duration, "duration")
    if positive_scalar(dt, "dt") > 2 * duration:  # not one step (steps = round(duration / dt))
        raise ValueError(f"dt: must be at most twice duration ({duration}) for one step, got {dt}")
    for name, value, low in (("seed", seed, 0), ("sample_every", sample_every, 1), ("rounds_per_step", rounds_per_step, 1)):
        if integer(value, name) < low:
            raise ValueError(f"{name}: must be >= {low}, got {value}")
    if not 0 <= loss < 1:
        raise ValueError(f"loss: must be in [0, 1), got {loss!r}")
    if bus is not None and loss:
        raise ValueError("bus: give either bus or loss, not both")
    if bus is not None and not isinstance(bus, BusConfig):
        raise TypeError(f"bus: must be a BusConfig, got {type(bus).__name__}")
    if runs is None:
        runs = [RunSpec(t, GainSchedule.paper(s)) for t in range(len(trees)) for s in SCHEMES]
    if bus is not None and bus.streams:
        raise ValueError("bus: run_balance gives every run its own stream (RunSpec.bus_seed); leave BusConfig.streams empty")
    runs = _checked_runs(runs, len(trees))
    instances = [trees[r.tree] for r in runs]
    built = [tree.to_model() for tree in trees]
    steps = round(duration / dt)
    samples = steps // sample_every + 1
    check_allocation(8 * samples * sum(built[r.tree][0].nq + 3 for r in runs), "duration")  # the sampled q and COM

    def start_seed(r: RunSpec) -> int:
        return seed + r.tree if r.start_seed is None else r.start_seed

    starts = {key: initial_angles(trees[key[0]], key[1]) for key in sorted({(r.tree, start_seed(r)) for r in runs})}
    plants = []
    for r in runs:
        model, layout = built[r.tree]
        q0 = np.zeros(model.nq)
        q0[layout.joint_q] = starts[(r.tree, start_seed(r))]
        plants.append(make_plant(plant, model, q0, dt, friction, r.ground))
    # Simulations step together, on every core; other plants one after another.
    simulations = [p for p in plants if isinstance(p, lk.Simulation)]
    batch = lk.SimulationBatch(simulations) if len(simulations) == len(plants) else None
    if batch is not None:
        pose_on_ground(batch, [built[r.tree][0] for r in runs])
    origin = np.zeros(3)
    first_module = np.cumsum([0] + [tree.n_modules for tree in instances])[:-1]
    n_modules = int(sum(tree.n_modules for tree in instances))
    ground = [GroundContact(int(m), 0, np.eye(3), origin, origin, np.array([0.0, 0.0, 1.0])) for m in first_module]
    if bus is None:
        bus = BusConfig() if loss == 0 else BusConfig(mode="async", loss=loss, seed=seed)
    if bus.mode == "async":
        bus = replace(bus, streams=tuple((tree.n_modules, start_seed(r) if r.bus_seed is None else r.bus_seed) for r, tree in zip(runs, instances)))
    module_slices = [slice(f, f + tree.n_modules) for f, tree in zip(first_module, instances)]
    noise = _SensorNoise(runs, module_slices, n_modules)

    # The plants' state in one call when they share their size (a gather of every run's joint angles), else plant by plant.
    sizes = {(built[r.tree][0].nq, built[r.tree][0].nv) for r in runs}
    shared_batch = batch if len(sizes) == 1 else None
    shared = shared_batch is not None
    if shared:
        nq, nv = sizes.pop()
        angle_index = np.concatenate([i * nq + built[r.tree][1].joint_q.ravel() for i, r in enumerate(runs)])
        tau_index = np.concatenate([i * nv + np.asarray(built[r.tree][0].idx_v)[built[r.tree][1].joint_bodies].ravel() for i, r in enumerate(runs)])

    def states() -> list[np.ndarray] | np.ndarray:
        return shared_batch.q if shared_batch is not None else [p.q for p in plants]

    def sensed_angles(q: list[np.ndarray] | np.ndarray) -> np.ndarray:
        if isinstance(q, np.ndarray):  # shared: the batch's (B, nq)
            angles = q.reshape(-1)[angle_index].reshape(-1, 3)
        else:
            angles = np.concatenate([built[r.tree][1].module_angles(q_run) for r, q_run in zip(runs, q)])
        return noise(angles)

    network = AgentNetwork(instances, bus=bus, ground=ground, angles=sensed_angles(states()))
    schedules = [r.schedule for r, tree in zip(runs, instances) for _ in range(tree.n_modules)]
    controller = BalanceController(network, schedules)
    # On the synchronous bus the agents and controller run compiled, one call per step; else in Python.
    kernel = BalanceKernel(controller) if network.bus.mode == "sync" else None
    (kernel or network).run_until_quiescent()  # the agents agree on a leader and the mass properties before moving
    joint_index = [np.asarray(built[r.tree][0].idx_v)[built[r.tree][1].joint_bodies] for r in runs]
    torque_limit = np.concatenate([np.full((tree.n_modules, 1), tree.parameters.servo_torque_limit) for tree in instances])

    def messages_sent() -> np.ndarray:
        if kernel is not None:
            return kernel.sent_by_module
        mass, election, pose = network.channels
        return mass.sent_by_module + election.sent_by_module + pose.sent_by_module

    def control(angles: np.ndarray) -> np.ndarray:
        if kernel is not None:
            return kernel.step(angles, dt, rounds_per_step)
        network.observe(angles)
        network.run(rounds_per_step)
        return controller.torques(dt)[0]

    messages_before = messages_sent()

    times = np.arange(samples) * sample_every * dt
    coms = np.zeros((samples, len(runs), 3))
    qs = [np.zeros((samples, built[r.tree][0].nq)) for r in runs]
    energy = np.zeros(len(runs))
    for step in progress_bar(range(steps + 1), enabled=progress, desc="balance", unit="step", mininterval=0.5):
        q = states()
        if step % sample_every == 0:
            for q_run, q_now in zip(qs, q):
                q_run[step // sample_every] = q_now
            coms[step // sample_every] = [lk.center_of_mass(built[r.tree][0], q_run[step // sample_every]) for r, q_run in zip(runs, qs)]
        if step == steps:
            break
        # The servos' motors cannot exceed their stall torque (ModuleParameters.servo_torque_limit).
        torque = np.clip(control(sensed_angles(q)), -torque_limit, torque_limit)
        taus: np.ndarray | list[np.ndarray]
        if shared:
            taus = np.zeros((len(runs), nv))
            taus.reshape(-1)[tau_index] = torque.reshape(-1)
        else:
            taus = []
            for r, index, modules in zip(runs, joint_index, module_slices):
                tau = np.zeros(built[r.tree][0].nv)
                tau[index] = torque[modules]
                taus.append(tau)
        if batch is not None:
            batch.step(taus)
            if shared:
                energy += np.abs(np.array([p.applied_tau for p in simulations]) * batch.v).sum(axis=1) * dt
            else:
                energy += [np.abs(p.applied_tau * p.v).sum() * dt for p in simulations]
        else:
            for p, tau in zip(plants, taus):
                p.step(tau)
            energy += [np.abs(tau * p.v).sum() * dt for p, tau in zip(plants, taus)]

    sent = messages_sent() - messages_before
    width = trees[0].parameters.width
    offsets = coms[..., :2]
    distance = np.linalg.norm(offsets, axis=-1) / width
    initial_direction = offsets[0] / np.maximum(np.linalg.norm(offsets[0], axis=-1, keepdims=True), 1e-300)
    signed = np.sum(offsets * initial_direction, axis=-1) / width
    return [
        RunResult(
            r.tree, r.schedule.scheme, times, distance[:, i], signed[:, i],
            float(sent[module_slices[i]].sum() / instances[i].n_modules / duration), qs[i], float(energy[i]), r.schedule,
        )
        for i, r in enumerate(runs)
    ]


def _checked_runs(runs: Sequence[RunSpec], n_trees: int) -> list[RunSpec]:
    """``runs`` as a list, each checked (ValueError or TypeError naming ``runs`` and the field)."""
    runs = list(runs)
    if not runs:
        raise ValueError("runs: need at least one run")
    for k, r in enumerate(runs):
        if not isinstance(r, RunSpec):
            raise TypeError(f"runs[{k}]: must be a RunSpec, got {type(r).__name__}")
        if not is_integer(r.tree) or not 0 <= r.tree < n_trees:
            raise ValueError(f"runs[{k}].tree: must be an index into trees (0..{n_trees - 1}), got {r.tree!r}")
        if not isinstance(r.schedule, GainSchedule):
            raise TypeError(f"runs[{k}].schedule: must be a GainSchedule, got {type(r.schedule).__name__}")
        if r.ground is not None and not isinstance(r.ground, lk.Ground):
            raise TypeError(f"runs[{k}].ground: must be an lk.Ground or None, got {type(r.ground).__name__}")
        positive_scalar(r.noise, f"runs[{k}].noise", allow_zero=True)
        for field in ("start_seed", "bus_seed", "noise_seed"):
            seed = getattr(r, field)
            if (seed is not None or field == "noise_seed") and (not is_integer(seed) or seed < 0):
                raise ValueError(f"runs[{k}].{field}: must be {'' if field == 'noise_seed' else 'None or '}an int >= 0, got {seed!r}")
    return runs


INITIAL_SPREAD = 0.25
INITIAL_LEAN = 0.5
POSE_KP = 20.0
POSE_KD = 1.0
POSE_DURATION = 0.5
NOISE_CHUNK = 256  # control steps of sensor noise drawn at a time
