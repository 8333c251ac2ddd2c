"""Every argument of every public callable of `legkit`, given a value of a type no argument accepts, raises an
error whose message names that argument (docs/errors.md). The others are given valid values, so that it is
the one that fails."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest

import legkit as lk

CHAIN = """<robot name="r"><link name="base"/><link name="l1"><inertial><mass value="1"/>
<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""
MJCF = """<mujoco><worldbody><body name="b"><joint name="j" type="hinge"/><geom size="0.1" mass="1"/></body>
</worldbody><actuator><motor joint="j"/></actuator></mujoco>"""


class Unconvertible:
    """A value of a type no argument takes: not a number, a string, a sequence, None or a legkit object."""


def instances() -> dict[str, object]:
    model = lk.Model.from_urdf(CHAIN)
    return {
        "MassProperties": lk.MassProperties.point(1.0, [0, 0, 0]),
        "Model": model,
        "Mjcf": lk.load_mjcf(MJCF),
        "Simulation": lk.Simulation(model),
        "SimulationBatch": lk.SimulationBatch([lk.Simulation(model)]),
        "Ground": lk.Ground.plane(),
    }


def valid(objects: dict[str, object]) -> dict[str, object]:
    """A value each argument name accepts, wherever it appears (OVERRIDES: where one name takes another kind)."""
    model = objects["Model"]
    assert isinstance(model, lk.Model)
    zero, three, up = np.zeros(model.nv), [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]
    return {
        "model": model, "q": model.neutral(), "v": zero, "a": zero, "tau": zero, "f_ext": None, "q0": model.neutral(),
        "q1": model.neutral(), "body": 1, "point": three, "frame": "local_world_aligned", "contacts": [(1, three)],
        "dim": 3, "independent": None, "dt": 0.01, "steps": 1, "method": "rk4", "mass": 1.0, "com": three,
        "inertia": np.eye(3), "masses": [1.0], "positions": [three], "position": three, "size": [1.0, 1.0, 1.0],
        "center": three, "rotation": np.eye(3), "translation": None, "other": objects["MassProperties"], "rtol": 1e-9,
        "atol": 1e-12, "floating_base": False, "base": None, "base_name": "base", "gravity": None, "parent": 0,
        "axis": up, "pitch": 0.1, "placement": None, "name": None, "limits": None,
        "mass_properties": objects["MassProperties"], "shapes": None, "path_or_xml": CHAIN, "strict": False,
        "package_dirs": None, "filename": "m.stl", "urdf": None, "ctrl": [0.0], "ground": None,
        "self_collision": False, "substeps": 1, "backend": "tree", "solver_iterations": 10, "friction_law": "coulomb",
        "kp": 1.0, "kd": None, "torque_limit": None, "target_q": None, "target_v": None, "n": 1, "targets": None,
        "simulations": [objects["Simulation"]], "heights": np.zeros((2, 2)), "cell_size": 0.1, "friction": 0.8,
        "normal": up, "radius": 1.0, "line_point": three, "line_direction": [1.0, 0.0, 0.0], "axis_point": three,
        "axis_direction": up, "weights": up, "controls": np.zeros((2, model.nv)), "jacobians": False,
    }


OVERRIDES = {"Model.add_" + kind: {"body": "MassProperties"} for kind in ("revolute", "prismatic", "helical", "spherical", "fixed")}


def callables() -> dict[str, object]:
    """Every public function, class and public method of `legkit`, by dotted name."""
    found: dict[str, object] = {}
    for name in lk.__all__:
        value = getattr(lk, name)
        if inspect.isclass(value) and issubclass(value, Warning):
            continue
        if callable(value) and not dataclasses.is_dataclass(value):  # a result's record is not called
            found[name] = value
        if inspect.isclass(value) and value.__module__ == "legkit":
            for attribute in vars(value):
                if not attribute.startswith("_") and callable(getattr(value, attribute)):
                    found[f"{name}.{attribute}"] = getattr(value, attribute)
    return found


def cases() -> list[tuple[str, str]]:
    found = []
    for name, function in callables().items():
        try:
            parameters = inspect.signature(function).parameters
        except ValueError:  # no signature: takes no arguments
            continue
        # **options pass through to another callable, walked there.
        found += [(name, p) for p, parameter in parameters.items() if p != "self" and parameter.kind != parameter.VAR_KEYWORD]
    return found


CASES = cases()


def test_the_walk_covers_the_api():
    names = {name for name, _ in CASES}
    assert {"aba", "Simulation", "Simulation.step", "Model.add_revolute", "Ground.heightfield"} <= names
    assert len(CASES) > 150, len(CASES)


@pytest.mark.parametrize(("name", "argument"), CASES, ids=[f"{n}-{a}" for n, a in CASES])
def test_a_wrong_typed_argument_is_named_in_the_message(name, argument):
    objects = instances()
    values = valid(objects)
    values |= {key: objects[kind] for key, kind in OVERRIDES.get(name, {}).items()}
    function = callables()[name]
    parameters = [p for p in inspect.signature(function).parameters.values() if p.name != "self" and p.kind != p.VAR_KEYWORD]
    owner, _, method = name.partition(".")
    bound = method and isinstance(inspect.getattr_static(getattr(lk, owner), method), type(lk.Model.neutral))
    if bound:
        function = getattr(objects[owner], method)
    at = [p.name for p in parameters].index(argument)
    # Valid values before it and for the required ones after it (converted later, or never).
    arguments = {p.name: values[p.name] for p in parameters[:at] + [p for p in parameters[at:] if p.default is p.empty]}
    arguments[argument] = Unconvertible()
    with pytest.raises((TypeError, ValueError, OverflowError)) as error:
        function(**arguments)
    assert argument in str(error.value), (name, arguments, str(error.value))
