"""Hostile forms and protocols: arrays in every dtype, layout and wrapper NumPy has; objects copied, pickled,
shared and mutated; signatures as `inspect` shows them.

An array argument given in any form NumPy reads as real numbers gives exactly the answer of the same numbers as a
plain C-ordered float64 array; a form whose numbers are not real (complex, strings, dates, records), a masked array
with masked entries and a Python int beyond float64's range are refused by name. Returned arrays are copies, and a
Simulation does not follow a Model changed after it was built.
"""

from __future__ import annotations

import array
import ast
import copy
import inspect
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest

import legkit as lk
from legkit import _core
from legkit.robots import build_quadruped
from test_hostile import GIB, raises


@pytest.fixture(scope="module")
def quadruped() -> lk.Model:
    return build_quadruped().model


def state(model: lk.Model) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(7)
    q = model.neutral()
    q[7:] = rng.normal(size=model.nq - 7) * 0.3
    return q, rng.normal(size=model.nv)


def read_only(x: np.ndarray) -> np.ndarray:
    y = x.copy()
    y.flags.writeable = False
    return y


# Forms of an array x that hold the same real numbers (each as NumPy converts it to float64); the last five, of a
# vector only.
SAME_NUMBERS = {
    "float32": lambda x: x.astype(np.float32),
    "int64": lambda x: np.round(x).astype(np.int64),
    "uint8": lambda x: np.abs(np.round(x)).astype(np.uint8),
    "bool": lambda x: x > 0,
    "big-endian": lambda x: x.astype(">f8"),
    "longdouble": lambda x: x.astype(np.longdouble),
    "object": lambda x: x.astype(object),
    "strided": lambda x: np.repeat(x[..., None], 2, axis=-1)[..., 0],
    "negative stride": lambda x: x[::-1].copy()[::-1],
    "Fortran-ordered slice": lambda x: np.asfortranarray(np.stack([x, x], axis=-1))[..., 0],
    "read-only": read_only,
    "broadcast_to": lambda x: np.broadcast_to(x, (3, *x.shape))[1],
    "list": lambda x: x.tolist(),
    "unmasked masked array": lambda x: np.ma.masked_array(x),
    "tuple": lambda x: tuple(x.tolist()),
    "array.array": lambda x: array.array("d", x),
    "memoryview": lambda x: memoryview(x.copy()),
    "list of NumPy scalars": lambda x: [np.float32(e) for e in x],
}
ANY_SHAPE = list(SAME_NUMBERS)[:-4]

# Forms refused: (form, error class, words of the message).
REFUSED = {
    "complex": (lambda x: x.astype(complex), TypeError, "complex128"),
    "complex, zero imaginary part": (lambda x: x + 0j, TypeError, "complex128"),
    "strings": (lambda x: x.astype(str), TypeError, "<U"),
    "datetime": (lambda x: np.zeros(x.shape, "M8[s]"), TypeError, "datetime64"),
    "record": (lambda x: np.zeros(x.shape, [("a", "f8")]), TypeError, "real numbers"),
    "masked entries": (lambda x: np.ma.masked_array(x, mask=np.arange(x.size).reshape(x.shape) == 0), ValueError, "masked"),
    "int beyond float64": (lambda x: np.full(x.shape, 10**400, dtype=object), ValueError, "float64's range"),
    "ragged": (lambda x: [x.tolist(), [1.0]], TypeError, "array of numbers"),
}


def calls(model: lk.Model):
    """(name, argument, its plain value, the call with the argument replaced)."""
    q, v = state(model)
    a = np.linspace(-1.0, 1.0, model.nv)
    foot = model.nbodies - 1
    point = np.array([0.1, -0.2, 0.3])
    return [
        ("rnea", "a", a, lambda x: lk.rnea(model, q, v, x)),
        ("aba", "v", v, lambda x: lk.aba(model, q, x, a)),
        ("crba", "q", q, lambda x: lk.crba(model, x)),
        ("jacobian", "point", point, lambda x: lk.jacobian(model, q, foot, x)),
        ("contact_dynamics", "tau", a, lambda x: lk.contact_dynamics(model, q, v, x, [(foot, point)])[0]),
        ("free_rollout", "v", v, lambda x: lk.free_rollout(model, q, x, dt=1e-3, steps=3)[1]),
        ("MassProperties.point", "position", point, lambda x: lk.MassProperties.point(2.0, x).com),
        ("circle_line", "center", point, lambda x: lk.circle_line(x, [0, 0, 1], 1.0, [0.5, 0, 0], [0, 1, 0]).circle_points),
    ]


def test_every_form_of_the_same_numbers_gives_the_same_answer(quadruped):
    for name, argument, plain, call in calls(quadruped):
        for form, make in SAME_NUMBERS.items():
            given = make(plain)
            expected = call(np.ascontiguousarray(np.asarray(given, dtype=np.float64)))
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                got = call(given)
            assert np.array_equal(got, expected), (name, argument, form)


def test_forms_that_are_not_real_numbers_are_refused_by_name(quadruped):
    for name, argument, plain, call in calls(quadruped):
        for form, (make, error, words) in REFUSED.items():
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # a ComplexWarning would mean it was converted
                with pytest.raises(error) as raised:
                    call(make(plain))
            assert str(raised.value).startswith(f"{argument}: ") and words in str(raised.value), (name, form, raised.value)


def test_a_complex_state_is_not_read_as_its_real_part(quadruped):
    q, v = state(quadruped)
    with pytest.raises(TypeError, match="^v: expected real numbers"):
        lk.rnea(quadruped, q, v + 1e-3j, np.zeros(quadruped.nv))


# --- Returned arrays, stored state and the Model a Simulation was built from ------------------------------


def test_returned_arrays_are_copies(quadruped):
    sim = lk.Simulation(quadruped)
    sim.step(None, 3)
    before = (sim.q.copy(), sim.v.copy(), sim.applied_tau.copy(), sim.body_poses().copy())
    for returned in (sim.q, sim.v, sim.applied_tau, sim.body_poses()):
        returned[...] = 7.0
    for value in sim.contacts().values():
        if isinstance(value, np.ndarray) and value.dtype != object:
            value[...] = 7
    assert all(np.array_equal(a, b) for a, b in zip(before, (sim.q, sim.v, sim.applied_tau, sim.body_poses())))
    batch = lk.SimulationBatch([sim])
    batch.q[...] = 7.0
    assert np.array_equal(batch.q[0], before[0])
    mp = lk.MassProperties.point(1.0, [1, 2, 3])
    mp.com[...] = 0.0
    assert np.array_equal(mp.com, [1, 2, 3])


def test_inputs_changed_after_the_call_change_nothing_stored(quadruped):
    sim = lk.Simulation(quadruped)
    q = quadruped.neutral()
    q[2] = 0.5
    sim.q = q
    q[2] = 9.0
    assert sim.q[2] == 0.5
    heights = np.zeros((3, 3))
    ground = lk.Ground.heightfield(heights, 0.1)
    heights[...] = 4.0
    assert not ground.heights.any()


def test_a_simulation_keeps_the_model_it_was_built_from():
    model = build_quadruped().model
    sim, twin = lk.Simulation(model), lk.Simulation(build_quadruped().model)
    simulated = sim.model
    assert simulated is sim.model and simulated is not model
    model.damping = 5.0
    model.add_fixed(0, name="extra")
    assert not simulated.damping.any() and simulated.nbodies == model.nbodies - 1
    sim.step(None, 50)
    twin.step(None, 50)
    assert np.array_equal(sim.q, twin.q)
    for change in (lambda m: setattr(m, "damping", 1.0), lambda m: setattr(m, "armature", 1.0), lambda m: m.add_fixed(0)):
        with pytest.raises(ValueError, match="^model: a Simulation's model"):
            change(simulated)
    assert not simulated.damping.any() and not simulated.armature.any() and simulated.nbodies == model.nbodies - 1
    derived = simulated.with_body(1, lk.MassProperties.point(1.0, [0, 0, 0]))
    derived.damping = 1.0  # a new Model, the caller's to change


def test_the_same_array_as_two_arguments(quadruped):
    q, v = state(quadruped)
    both = v.copy()
    assert np.array_equal(lk.rnea(quadruped, q, both, both), lk.rnea(quadruped, q, v.copy(), v.copy()))
    assert np.array_equal(both, v)


# --- Object protocols -------------------------------------------------------------------------------------


def objects(model: lk.Model) -> dict[str, object]:
    return {
        "MassProperties": lk.MassProperties.point(1.0, [0, 0, 0]),
        "Model": model,
        "Simulation": lk.Simulation(model),
        "SimulationBatch": lk.SimulationBatch([lk.Simulation(model)]),
        "Ground": lk.Ground.heightfield(np.zeros((3, 3)), 0.1),
        "Mjcf": lk.load_mjcf('<mujoco><worldbody><body><joint type="hinge"/><geom size="0.1" mass="1"/></body></worldbody></mujoco>'),
    }


@pytest.mark.parametrize("protocol", [copy.copy, copy.deepcopy, lambda o: pickle.loads(pickle.dumps(o))], ids=["copy", "deepcopy", "pickle"])
def test_copying_a_binding_is_a_clear_type_error(quadruped, protocol):
    for name, value in objects(quadruped).items():
        with pytest.raises(TypeError, match=f"cannot pickle 'legkit.{name}'"):
            protocol(value)


def test_bindings_are_final_and_reprs_are_short(quadruped):
    for name, value in objects(quadruped).items():
        with pytest.raises(TypeError, match="not an acceptable base type"):
            type("Sub", (type(value),), {})
        assert len(repr(value)) < 200, name
    chain = lk.Model()
    for i in range(3000):
        chain.add_revolute(i, [0, 1, 0], body=lk.MassProperties.point(1.0, [0, 0, -0.1]))
    assert len(repr(chain)) < 200 and len(repr(lk.Simulation(chain))) < 200


# --- Signatures -------------------------------------------------------------------------------------------


def binding_signatures() -> dict[str, inspect.Signature]:
    """The signature `inspect` shows of every function, class and method of `legkit._core`."""
    found = {}
    for name, value in vars(_core).items():
        members = [(name, value)]
        if inspect.isclass(value) and not issubclass(value, Warning):
            members += [(f"{name}.{m}", getattr(value, m)) for m in vars(value) if not m.startswith("_")]
        for dotted, member in members:
            if callable(member) and not name.startswith("_"):
                try:
                    found[dotted] = inspect.signature(member)
                except ValueError:  # no parameters to show (a getter's type)
                    pass
    return found


def stub_defaults() -> dict[str, dict[str, object]]:
    """Each function and method's default values as _core.pyi writes them."""
    tree = ast.parse((Path(lk.__file__).parent / "_core.pyi").read_text())
    found: dict[str, dict[str, object]] = {}

    def add(dotted: str, function: ast.FunctionDef) -> None:
        arguments = function.args
        positional = arguments.posonlyargs + arguments.args
        pairs = list(zip(positional[len(positional) - len(arguments.defaults):], arguments.defaults))
        pairs += [(a, d) for a, d in zip(arguments.kwonlyargs, arguments.kw_defaults) if d is not None]
        found[dotted] = {a.arg: ast.literal_eval(d) for a, d in pairs}

    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            add(node.name, node)
        elif isinstance(node, ast.ClassDef):
            for member in node.body:
                if isinstance(member, ast.FunctionDef):
                    add(node.name if member.name == "__init__" else f"{node.name}.{member.name}", member)
    return found


def test_signatures_show_their_real_defaults_as_the_stubs_do():
    signatures, stubs = binding_signatures(), stub_defaults()
    assert {"Simulation", "SimulationBatch.step", "contact_dynamics", "impact"} <= signatures.keys()
    compared = 0
    for name, signature in signatures.items():
        for parameter in signature.parameters.values():
            assert parameter.default is not Ellipsis, (name, parameter)
            if parameter.default is not parameter.empty and parameter.name in stubs.get(name, {}):
                assert stubs[name][parameter.name] == parameter.default, (name, parameter)
                compared += 1
    assert compared > 40, compared


# --- The Python layers: the same rule through `_validation.real_numbers` -----------------------------------

FEET = np.array([[0.3, 0.2, 0.0], [0.3, -0.2, 0.0], [-0.3, -0.2, 0.0], [-0.3, 0.2, 0.0]])
TOES = np.array([[0.1, 0.1, -0.2], [0.1, -0.1, -0.21], [-0.1, 0.0, -0.19]])


def python_calls():
    from legkit import stability, strain

    com = np.array([0.01, 0.02, 0.3])
    forces = np.array([[0.1, 0.2, 10.0]] * 4)
    return [
        ("static_stability_margin", "contact_points", FEET, lambda x: stability.static_stability_margin(com, x)),
        ("center_of_pressure", "forces", forces, lambda x: stability.center_of_pressure(FEET, x)),
        ("friction_cone_margin", "normals", np.tile([0.0, 0.0, 1.0], (4, 1)), lambda x: stability.friction_cone_margin(forces, x, 0.7)),
        ("zmp_from_momentum_rate", "com", com, lambda x: stability.zmp_from_momentum_rate(x, np.arange(6.0), 10.0)),
        ("tripod_pose", "toes", TOES, lambda x: strain.tripod_pose(x).position),
        ("nrmse", "d_hat", np.array([1.1, 2.0, 2.9]), lambda x: strain.nrmse([1.0, 2.0, 3.0], x)),
        ("tripod_clock_signal", "hip_angle", np.linspace(-1, 1, 12).reshape(2, 6), strain.tripod_clock_signal),
    ]


def test_python_layers_give_the_same_answer_for_every_form_of_the_same_numbers():
    for name, _, plain, call in python_calls():
        for form in (f for f in (ANY_SHAPE if plain.ndim > 1 else SAME_NUMBERS) if f not in ("int64", "uint8", "bool")):  # rounded: degenerate
            given = SAME_NUMBERS[form](plain)
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                assert np.array_equal(call(given), call(np.asarray(given, dtype=np.float64))), (name, form)


def test_python_layers_refuse_numbers_that_are_not_real_by_name():
    for name, argument, plain, call in python_calls():
        for form, (make, error, _) in REFUSED.items():
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                with pytest.raises(error) as raised:
                    call(make(plain))
            assert str(raised.value).startswith(argument), (name, form, raised.value)


def test_an_agent_network_keeps_its_own_ground_contacts():
    from legkit.agents import AgentNetwork, GroundContact
    from legkit.robots import random_tree

    tree = random_tree(4, seed=1)
    point, direction = np.zeros(3), np.array([1.0, 0.0, 0.0])
    contact = GroundContact(0, 0, np.eye(3), np.zeros(3), point, direction)
    network = AgentNetwork(tree, ground=[contact])
    point[...] = 5.0
    direction[...] = 0.0
    assert not network.ground[0].line_point.any() and network.ground[0].line_direction[0] == 1.0
    for field, value, error in (("line_point", [0.0, 0.0j, 0.0], TypeError), ("translation", [0.0, 0.0], ValueError),
                                ("rotation", np.full((3, 3), np.nan), ValueError)):
        bad = GroundContact(**{**vars(contact), field: value})
        with pytest.raises(error, match=rf"^ground\[0\]\.{field}"):
            AgentNetwork(tree, ground=[bad])


# --- Sweeps and callbacks: bounded before anything is spelled out, started or run (child processes) ---------

SWEEP = "from legkit.sweeps import SweepSpec, run_sweep\nspec = SweepSpec(trees=1, schemes=['constant'], duration=0.02, modules=3, branches=1)\n"


@pytest.mark.parametrize(
    ("call", "expected", "words"),
    [
        ("SweepSpec(trees=10**12)", "ValueError", "trees: must be in 1..1000000"),
        ("SweepSpec(seeds=2**70)", "ValueError", "seeds: must be in 1..1000000"),
        ("SweepSpec(trees=list(range(10**7)))", "ValueError", "trees: at most 1000000 values"),
        ("SweepSpec(kp0=np.arange(1000.0), ki0=np.arange(1000.0), kd0=np.arange(1000.0))", "ValueError", "spec: the grid has 12000000000 runs"),
        ("SweepSpec(modules=10**9)", "ValueError", "modules: must be in 1..1000"),
        ("SweepSpec(delay=[2**64])", "ValueError", "delay: must be in 1..1000000"),
        ("SweepSpec(duration=1e300, dt=1e-300)", "ValueError", "duration: at most"),
        ("run_sweep(spec, out, workers=10**9, progress=False)", "ValueError", "workers: must be an int in 1..1024"),
        ("run_sweep(spec, out, workers=1, threads=10**9, progress=False)", "ValueError", "threads: must be an int in 1..1024"),
        ("run_sweep(spec, out, workers=1, log=5, progress=False)", "TypeError", "log: must be a callable"),
        ("run_sweep(spec, out, ray=5, progress=False)", "TypeError", "ray: must be an address"),
        ("run_sweep(spec, '/dev/null/sweep', workers=1, progress=False, figures=False)", "ValueError", "out: cannot create"),
    ],
)
def test_hostile_sweeps_are_refused_by_name_at_once(call, expected, words, tmp_path):
    raises(SWEEP + f"out = {str(tmp_path / 'sweep')!r}\n" + call, expected, words, timeout=60, memory=4 * GIB)


def test_a_gait_analysis_refuses_a_progress_that_cannot_be_called():
    from legkit.gaits import analyse

    with pytest.raises(TypeError, match="^progress: must be a callable"):
        analyse("robot", lk.Model(), None, None, 1.0, 0.5, progress=5)  # type: ignore[arg-type]


def test_a_bool_or_a_complex_scalar_is_not_taken_for_a_number(quadruped):
    q = quadruped.neutral()
    calls = {
        "dt": lambda: lk.Simulation(quadruped, dt=True),
        "n": lambda: lk.Simulation(quadruped).step(None, True),
        "mass": lambda: lk.MassProperties.point(True, [0, 0, 0]),
        "friction": lambda: lk.Ground.plane(friction=False),
        "steps": lambda: lk.free_rollout(quadruped, q, np.zeros(quadruped.nv), dt=1e-3, steps=True),
        "dim": lambda: lk.impact(quadruped, q, np.zeros(quadruped.nv), [(1, [0, 0, 0])], dim=True),
        "body": lambda: lk.jacobian(quadruped, q, True),
    }
    for argument, call in calls.items():
        with pytest.raises(TypeError, match=f"^{argument}: expected an? (real number|integer|index)"):
            call()
    for complex_scalar in (np.complex128(0.01), np.complex64(0.01), np.array(0.01 + 0j)):  # NumPy would warn and drop .imag
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(TypeError, match="^dt: expected a real number, got a complex number"):
                lk.Simulation(quadruped, dt=complex_scalar)
    with pytest.raises(TypeError, match="^shapes: sphere parameters must be numbers"):
        lk.Simulation(quadruped, shapes={1: ("sphere", True)})
    with pytest.raises(TypeError, match="^limits: upper must be a number"):
        lk.Model().add_revolute(0, [0, 0, 1], limits={"upper": True})
    with pytest.raises(TypeError, match="^limits: lower must be a number"):  # read as (1.0, 2.0) before
        lk.Model().add_revolute(0, [0, 0, 1], limits=(True, 2.0))
    assert lk.Simulation(quadruped, dt=np.float32(0.5)).dt == 0.5 and lk.jacobian(quadruped, q, np.int8(1)).shape == (6, quadruped.nv)


def test_the_strain_experiment_checks_its_walking_source(tmp_path):
    from legkit.experiments import strain as experiment

    for source, words in ((5, "source: must be a WalkingSource"), (lambda speed, duration, seed: None, "source: returned NoneType")):
        with pytest.raises(TypeError, match=words):
            experiment.run(tmp_path, source=source, runs=1, duration=0.5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="^runs must be an integer"):
        experiment.run(tmp_path, runs=2.5)  # type: ignore[arg-type]


def test_a_walking_record_too_long_to_hold_is_refused_before_allocating():
    raises("from legkit.strain import kinematic_walk\nkinematic_walk(0.2, 1e5)", "ValueError", "duration: 100000.0 s at 300.0 Hz")


def test_masked_group_ids_are_refused():
    from legkit.strain import average_by_group

    with pytest.raises(ValueError, match="^groups is a masked array"):
        average_by_group(np.ma.masked_array([0, 1, 0], mask=[0, 1, 0]), [1.0, 2.0, 3.0])
