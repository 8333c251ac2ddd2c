"""Hostile input: huge sizes, deep or pathological files, out-of-range integers, overflowing numbers, Ctrl-C.

Each case runs in a child interpreter with a timeout and an address-space limit, so a crash (a signal, an
abort, a Rust panic) or a hang fails its test instead of the run. A case passes when the child raises the
class of the error table (docs/errors.md), with a message naming the argument, and exits normally.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import legkit as lk
from conftest import ctrl_c_restored

GIB = 1 << 30

PRELUDE = """
import json, resource, sys
limit = {memory}
if limit:
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
import numpy as np
import legkit as lk

def report(**fields):
    print("RESULT " + json.dumps(fields), flush=True)

try:
{body}
except BaseException as error:
    report(raised=type(error).__name__, message=str(error))
else:
    report(raised=None)
"""


def outcome(body: str, *, timeout: float = 30.0, memory: int = 2 * GIB, cwd: Path | None = None) -> dict:
    """What `body` did in a child interpreter: its first `report(...)`, or {"raised": class name or None,
    "message": ...}. A crash or a timeout fails the calling test."""
    code = PRELUDE.format(memory=memory, body=textwrap.indent(textwrap.dedent(body).strip(), "    "))
    child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, cwd=cwd)
    results = [line for line in child.stdout.splitlines() if line.startswith("RESULT ")]
    assert child.returncode == 0 and results, f"the child crashed (exit {child.returncode}):\n{child.stderr[-3000:]}"
    result = json.loads(results[0].removeprefix("RESULT "))
    assert result.get("raised") != "PanicException", result
    return result


def raises(body: str, expected: str, *words: str, **options) -> dict:
    result = outcome(body, **options)
    assert result["raised"] == expected, result
    for word in words:
        assert word in result["message"], result
    return result


PENDULUM = """
model = lk.Model()
model.add_revolute(0, [0, 1, 0], placement=(np.eye(3), [0, 0, 0]), body=lk.MassProperties.point(1.0, [0, 0, -0.5]), name="link")
q, v, tau = np.zeros(1), np.zeros(1), np.zeros(1)
"""


def chain_urdf(links: int) -> str:
    """A URDF chain of `links` links on revolute joints."""
    inertial = '<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
    parts = ['<robot name="chain">', f'<link name="l0">{inertial}</link>']
    for i in range(1, links):
        parts.append(f'<link name="l{i}">{inertial}</link>')
        parts.append(
            f'<joint name="j{i}" type="revolute"><parent link="l{i - 1}"/><child link="l{i}"/>'
            '<origin xyz="0 0 -0.1"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
        )
    parts.append("</robot>")
    return "\n".join(parts)


# --- MemoryError: a size that cannot be allocated, checked before allocating -------------------------------


def test_a_huge_broadcast_batch_is_a_memory_error():
    raises(
        PENDULUM + "lk.aba(model, np.broadcast_to(q, (10**5, 1, 1)), np.broadcast_to(v, (1, 10**5, 1)), tau)",
        "MemoryError",
        "bytes",
    )


def test_a_batch_whose_shape_product_overflows_is_a_memory_error():
    raises(
        PENDULUM
        + """
big = 2**31
lk.rnea(model, np.broadcast_to(q, (big, 1, 1, 1)), np.broadcast_to(v, (1, big, 1, 1)), np.broadcast_to(tau, (1, 1, big, 1)))
""",
        "MemoryError",
    )


@pytest.mark.parametrize("steps", [10**12, 2**63 - 1, 2**63, 2**64 - 1, 2**70])
def test_a_rollout_too_long_to_hold_is_a_memory_error(steps):
    raises(PENDULUM + f"lk.free_rollout(model, q, v, dt=1e-3, steps={steps})", "MemoryError", "steps")


@pytest.mark.parametrize(
    "call",
    [
        "lk.MassProperties.from_points(np.broadcast_to(1.0, (10**10,)), np.broadcast_to(0.0, (10**10, 3)))",
        'lk.Simulation(model, shapes={1: ("convex", np.broadcast_to(0.0, (10**10, 3)))})',
        "lk.reduced_dynamics(model, np.broadcast_to(0.0, (10**10,)), v, tau, [(1, [0, 0, 0])])",
    ],
)
def test_huge_broadcast_views_elsewhere_are_memory_errors(call):
    raises(PENDULUM + call, "MemoryError", "bytes")


def test_huge_broadcast_servo_targets_are_a_memory_error():
    raises(PENDULUM + "sim = lk.Simulation(model)\nsim.step(targets=np.broadcast_to(0.0, (10**10, 1)))", "MemoryError", "targets")


def test_a_batch_result_that_fits_once_but_not_twice_is_a_memory_error():
    # The kernels fill one packed block of rows, then split it into an array per result: the limit is set so
    # that the block (512 MiB) fits and its split copy does not.
    raises(
        PENDULUM
        + """
rows = 2**29 // (8 * 13 * model.nbodies)
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 3 * 2**28, vm + 3 * 2**28))
lk.subtree_mass_properties(model, np.broadcast_to(q, (rows, 1)))
""",
        "MemoryError",
        "bytes",
        memory=0,
    )


def test_a_rapier_simulation_of_a_model_too_large_for_its_dense_blocks_is_a_memory_error(tmp_path):
    # Rapier's multibody holds nv x nv matrices and a 6 x nv Jacobian per body: about 64 GB for 20,000 links.
    (tmp_path / "chain.urdf").write_text(chain_urdf(20_000))
    raises(f"model = lk.Model.from_urdf({str(tmp_path / 'chain.urdf')!r})\nlk.Simulation(model, backend='rapier')", "MemoryError", "model")


def test_a_huge_broadcast_heightfield_is_a_memory_error():
    raises("lk.Ground.heightfield(np.broadcast_to(0.0, (10**5, 10**5)), 0.1)", "MemoryError", "heights")


def binary_stl(path: Path, triangles: int, *, sphere: bool = False) -> None:
    """A binary STL of `triangles` triangles with vertices in the unit cube, or on the unit sphere (every vertex
    then on the hull)."""
    rng = np.random.default_rng(0)
    points = rng.normal(size=(triangles, 3, 3))
    if sphere:
        points /= np.linalg.norm(points, axis=2, keepdims=True)
    records = np.zeros(triangles, dtype=[("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
    records["vertices"] = points
    path.write_bytes(b"\0" * 80 + np.uint32(triangles).tobytes() + records.tobytes())


LIMITED = """
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + {headroom} * 2**20, vm + {headroom} * 2**20))
"""


def test_a_mesh_too_large_for_memory_is_a_memory_error(tmp_path):
    # 350 MB of headroom above what the child holds before loading, of which the loader's thread takes 72 MB (its
    # stack and malloc arena): the file (200 MB) fits, its vertex list (288 MB) does not.
    binary_stl(tmp_path / "leg.stl", 4_000_000)
    (tmp_path / "r.urdf").write_text(MESH_URDF.format(filename="leg.stl"))
    raises(LIMITED.format(headroom=350) + f"lk.Model.from_urdf({str(tmp_path / 'r.urdf')!r})", "MemoryError", "mesh", "leg.stl", "bytes", memory=0)


def test_a_mesh_whose_whole_hull_would_not_fit_loads_its_thinned_hull(tmp_path):
    # Parry's working set for the hull of 600,000 points on a sphere (about 700 MB) did not fit in 200 MB of
    # headroom; the hull is now taken over at most 25,000 of them (about 32 MB), with a warning.
    binary_stl(tmp_path / "leg.stl", 200_000, sphere=True)
    (tmp_path / "r.urdf").write_text(MESH_URDF.format(filename="leg.stl"))
    body = LIMITED.format(headroom=200) + f"""
import warnings
from collections.abc import Callable
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    lk.Model.from_urdf({str(tmp_path / "r.urdf")!r})
report(raised=None, warnings=[str(w.message) for w in caught])
"""
    result = outcome(body, memory=0)
    assert result["raised"] is None and any("convex hull is taken over" in w for w in result["warnings"]), result


def test_a_collada_file_instancing_a_geometry_beyond_memory_is_a_memory_error(tmp_path):
    # 2 MB of text: 100,000 vertices instanced 10,000 times, 24 GB of vertices.
    floats = " ".join(["0 0 0 1 0 0 0 1 0 0 0 1"] * 25_000)
    geometry = (
        f'<library_geometries><geometry id="g"><mesh><source id="p"><float_array>{floats}</float_array></source>'
        '<vertices id="v"><input semantic="POSITION" source="#p"/></vertices></mesh></geometry></library_geometries>'
    )
    nodes = '<node><instance_geometry url="#g"/></node>' * 10_000
    (tmp_path / "leg.dae").write_text(
        f"<COLLADA>{geometry}<library_visual_scenes><visual_scene>{nodes}</visual_scene></library_visual_scenes></COLLADA>"
    )
    (tmp_path / "r.urdf").write_text(MESH_URDF.format(filename="leg.dae"))
    raises(f"lk.Model.from_urdf({str(tmp_path / 'r.urdf')!r})", "MemoryError", "mesh", "leg.dae", "bytes", memory=GIB)


TINY_ELEMENTS = {
    "urdf": '<robot name="r"><link name="a"/>' + "<b/>" * 10**7 + "</robot>",
    "mjcf": "<mujoco><worldbody/>" + "<b/>" * 10**7 + "</mujoco>",
}


@pytest.mark.parametrize("source", ["xml", "path"])
@pytest.mark.parametrize("kind", ["urdf", "mjcf"])
def test_a_document_too_large_for_memory_is_a_memory_error(tmp_path, kind, source):
    # 40 MB of ten million empty elements: roxmltree's document (72 B a node, 720 MB) does not fit in 512 MB.
    (tmp_path / f"r.{kind}").write_text(TINY_ELEMENTS[kind])
    raises(
        f"""
path = {str(tmp_path / f"r.{kind}")!r}
argument = path if {source!r} == "path" else open(path).read()
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 512 * 2**20, vm + 512 * 2**20))
lk.Model.from_{kind}(argument)
""",
        "MemoryError",
        f"{source}: parsing 40000",
        "bytes",
        memory=0,
    )


def test_an_mjcf_model_too_large_for_memory_is_a_memory_error():
    # 1.5 million bodies in 10 MB: the document fits in 1 GB, the bodies built from it (1.1 KB each) do not.
    raises(
        """
xml = "<mujoco><worldbody>" + "<body/>" * 1_500_000 + "</worldbody></mujoco>"
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 2**30, vm + 2**30))
lk.Model.from_mjcf(xml)
""",
        "MemoryError",
        "xml: building a model of 1500002 elements",
        "bytes",
        memory=0,
        timeout=60,
    )


def test_rnea_and_aba_on_a_20000_link_chain_stay_within_100_mb(tmp_path):
    (tmp_path / "chain.urdf").write_text(chain_urdf(20_000))
    # The limit is set after loading: what the kernels allocate on top must fit in 100 MB.
    result = outcome(
        f"""
model = lk.Model.from_urdf({str(tmp_path / "chain.urdf")!r})
q, v = np.full(model.nq, 0.1), np.full(model.nv, 0.2)
lk.rnea(model, q, v, v)
status = open("/proc/self/status").read()
vm = int(status.split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 100 * 2**20, vm + 100 * 2**20))
tau = lk.rnea(model, q, v, v)
a = lk.aba(model, q, v, tau)
report(raised=None, finite=bool(np.isfinite(a).all()), error=float(np.abs(a - v).max() / np.abs(v).max()))
""",
        memory=0,
        timeout=60,
    )
    # ABA undoes RNEA to the conditioning of a 20,000-link chain.
    assert result["raised"] is None and result["finite"] and result["error"] < 1e-3, result


@pytest.mark.parametrize("call", ["lk.crba(model, q)", "lk.minv(model, q)", "lk.contact_dynamics(model, q, q, q, [(1, [0, 0, 0])])"])
def test_dense_kernels_on_a_20000_link_chain_are_memory_errors_within_a_limit(tmp_path, call):
    # Their output (3.2 GB) fits under the limit, their own nv x nv workspace does not: MemoryError, not an abort.
    (tmp_path / "chain.urdf").write_text(chain_urdf(20_000))
    raises(
        f"""
model = lk.Model.from_urdf({str(tmp_path / "chain.urdf")!r})
q = np.zeros(model.nq)
vm = int(open("/proc/self/status").read().split("VmSize:")[1].split()[0]) * 1024
resource.setrlimit(resource.RLIMIT_AS, (vm + 4 * 2**30, vm + 4 * 2**30))
{call}
""",
        "MemoryError",
        "model",
        "bytes",
        memory=0,
    )


# --- recursion over input-defined depth ---------------------------------------------------------------------


def test_a_collada_file_with_20000_nested_nodes_loads(tmp_path):
    depth = 20_000
    cube = " ".join(f"{x} {y} {z}" for x in (0, 1) for y in (0, 1) for z in (0, 1))
    geometry = (
        '<library_geometries><geometry id="g"><mesh><source id="p"><float_array count="24">'
        f'{cube}</float_array></source><vertices id="v"><input semantic="POSITION" source="#p"/></vertices>'
        "</mesh></geometry></library_geometries>"
    )
    nodes = "<node>" * depth + '<instance_geometry url="#g"/>' + "</node>" * depth
    (tmp_path / "deep.dae").write_text(
        f'<COLLADA>{geometry}<library_visual_scenes><visual_scene id="s">{nodes}</visual_scene></library_visual_scenes></COLLADA>'
    )
    urdf = (
        '<robot name="r"><link name="base"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>'
        '</inertial><collision><geometry><mesh filename="deep.dae"/></geometry></collision></link></robot>'
    )
    (tmp_path / "r.urdf").write_text(urdf)
    result = outcome(
        f"""
model = lk.Model.from_urdf({str(tmp_path / "r.urdf")!r}, strict=True)
report(raised=None, kinds=[c[1] for c in model.colliders()])
"""
    )
    assert result["kinds"] == ["convex"], result


NESTED_MJCF = """
def nested(depth):
    body = "<body pos='0 0 -0.1'><joint type='hinge'/><geom size='0.05'/>"
    return "<mujoco><worldbody>" + body * depth + "</body>" * depth + "</worldbody></mujoco>"
"""


def test_an_mjcf_file_nested_1000_deep_loads_and_deeper_is_refused():
    # <mujoco> is at depth 0, <worldbody> at 1, and the deepest body's joint and geom one below it.
    result = outcome(NESTED_MJCF + "report(raised=None, nbodies=lk.Model.from_mjcf(nested(998)).nbodies)")
    assert result == {"raised": None, "nbodies": 999}
    raises(NESTED_MJCF + "lk.Model.from_mjcf(nested(100_000))", "ValueError", "mjcf", "nest deeper than 1000 levels")
    defaults = """
classes = "".join(f"<default class='c{i}'>" for i in range(100_000))
lk.Model.from_mjcf("<mujoco><default>" + classes + "</default>" * 100_001 + "</mujoco>")
"""
    raises(defaults, "ValueError", "mjcf", "nest deeper than 1000 levels")


# --- dependencies that can panic -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "defaults",
    [
        ('<default><default class="a"><default class="a"/></default></default>', "defined twice"),
        ('<default><default class="a"/><default class="a"/></default>', "defined twice"),
        ('<default><default class="main"/></default>', "defined twice"),
        ('<default class="a"/>', "cannot be renamed"),
    ],
    ids=["nested", "siblings", "main", "top-renamed"],
)
def test_a_default_class_defined_twice_or_a_renamed_top_class_is_refused(defaults):
    # A nested class of its parent's name silently replaced the parent's attributes, and a top <default class="a">
    # was read as "main" (MuJoCo refuses both).
    xml, reason = defaults
    raises(f"lk.Model.from_mjcf('<mujoco>{xml}<worldbody/></mujoco>')", "ValueError", "mjcf", reason)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        ("run_balance([tree], 0.01, sample_every=0)", "sample_every"),  # was a ZeroDivisionError
        ("run_balance([tree], 0.01, rounds_per_step=0)", "rounds_per_step"),  # ran without messages
        ("run_balance([tree], 0.01, dt=1.0)", "dt"),  # ran no step and returned the start
        ("run_balance([tree], 0.01, seed=-1)", "seed"),  # NumPy's message, naming nothing
        ("initial_angles(tree, -1)", "seed"),
        ("PID((-1,))", "shape"),
    ],
)
def test_balance_entry_points_refuse_bad_counts_by_name(call, name):
    setup = "from legkit.control import PID, initial_angles, run_balance\nfrom legkit.robots import random_tree\ntree = random_tree(5, 2)\n"
    raises(setup + call, "ValueError", name)


@pytest.mark.parametrize(
    ("call", "error", "name"),
    [
        ("random_tree(10**9)", "ValueError", "n_modules"),  # ran for hours before failing to place the modules
        ("PID((10**6, 10**6))", "MemoryError", "shape"),  # NumPy's MemoryError, naming nothing
        ("PID((10**10, 10**10))", "MemoryError", "shape"),  # NumPy's ValueError about the byte count
        ("quadruped_amble(build_quadruped(), 0.67, 0.4, 10**9, 1, 0.03, 0.09)", "ValueError", "samples"),  # ran out of memory
        ("quadruped_amble(build_quadruped(), 0.67, 0.4, 400, 10**6, 0.03, 0.09)", "ValueError", "cycles"),
        ("build_quadruped('x')", "TypeError", "parameters"),  # was an AttributeError
        ("build_biped(3)", "TypeError", "parameters"),
        ("random_tree(5, parameters='x')", "TypeError", "parameters"),
        ("QuadrupedParameters(torso_size='abc')", "TypeError", "torso_size"),  # was a str/float comparison error
        ("QuadrupedParameters(thigh_length=1e300)", "ValueError", "thigh_length"),  # blamed the core's 'inertia'
        ("QuadrupedParameters(hip_x=float('nan'))", "ValueError", "hip_x"),  # a NaN model
        ("BipedParameters(torso_position=(0, 0, float('inf')))", "ValueError", "torso_position"),
        ("ModuleParameters(width=1e300)", "ValueError", "width"),  # blamed the root's connector
        ("MotorParameters(-1, 0.1, 10, 0.9, 5, 1)", "ValueError", "resistance"),  # accepted: a negative Joule loss
        ("MotorParameters(float('nan'), 0.1, 10, 0.9, 5, 1)", "ValueError", "resistance"),
        ("MotorParameters(1, 0.1, 10, 1.5, 5, 1)", "ValueError", "efficiency"),
        ("rhex_compliant_model('x')", "TypeError", "spring_axis"),  # NumPy's conversion message
        ("model_to_urdf(build_quadruped().model, 5)", "TypeError", "robot_name"),
        ("model_to_urdf('m', 'q')", "TypeError", "model"),
        ("initial_angles('x', 0)", "TypeError", "tree"),
        ("FreePlant('m')", "TypeError", "model"),
        ("run_balance(['x'], 0.01)", "TypeError", "trees[0]"),
        ("run_balance(random_tree(5, 2), 0.01)", "TypeError", "trees"),
        ("run_balance([random_tree(5, 2)], 1e12)", "MemoryError", "duration"),  # NumPy's 728 TiB message
        ("run_balance([random_tree(5, 2)], 0.01, dt=1e-300)", "MemoryError", "duration"),  # blamed the core's 'n'
        ("build_biped().leg_angles('x', [0, 0.1, -0.7])", "ValueError", "side"),  # the right leg's angles
        ("build_biped().joint_slice('l', 'tail')", "ValueError", "limb"),  # the arm's slice
        ("build_biped().contacts(('x',))", "ValueError", "sides"),  # a KeyError
        ("build_quadruped().contacts('lf')", "TypeError", "legs"),  # a KeyError for 'l'
        ("build_quadruped().joint_slice('zz')", "ValueError", "leg"),  # "'zz_hip' is not in list"
        ("build_quadruped().leg_angles('lf', [0, 0])", "ValueError", "foot_in_torso"),  # NumPy's broadcast error
        ("GainSchedule('distance').gains(float('nan'), 0.1)", "ValueError", "distance_widths"),  # NaN gains
        ("run_balance([random_tree(5, 2)], 0.01, runs=[RunSpec(0, GainSchedule(), noise_seed=-1)])", "ValueError", "noise_seed"),
        ("pose_on_ground('b', [])", "TypeError", "batch"),  # an AttributeError
        ("m = random_tree(5, 2).to_model()[0]\npose_on_ground(lk.SimulationBatch([lk.Simulation(m)]), [m, m])", "ValueError", "models"),
    ],
)
def test_robot_and_control_entry_points_name_a_bad_argument_or_size(call, error, name):
    setup = (
        "from legkit.control import PID, FreePlant, GainSchedule, RunSpec, initial_angles, pose_on_ground, run_balance\n"
        "from legkit.robots import *\nfrom legkit.gaits.references import quadruped_amble\n"
    )
    raises(setup + call, error, name)


def test_a_capsule_beyond_any_robot_is_refused_before_parry_sees_it():
    raises(
        PENDULUM
        + """
model.add_revolute(1, [0, 1, 0], placement=(np.eye(3), [0, 0, -1]), body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
model.add_revolute(2, [0, 1, 0], placement=(np.eye(3), [0, 0, -1]), body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
sim = lk.Simulation(model, shapes={1: ("capsule", 1e155, 0.1), 3: ("capsule", 1e155, 0.1)}, self_collision=True)
sim.step(None, 5)
""",
        "ValueError",
        "shapes",
    )


# --- integer arguments out of range --------------------------------------------------------------------------


@pytest.mark.parametrize("body", ["2**70", "-2**70", "5"])
def test_a_body_index_out_of_range_is_an_index_error(body):
    raises(PENDULUM + f"lk.jacobian(model, q, {body}, [0, 0, 0])", "IndexError", "body")


def test_an_unknown_body_in_shapes_is_an_index_error():
    raises(PENDULUM + 'lk.Simulation(model, shapes={"nope": ("sphere", 0.1)})', "IndexError", "shapes", "nope")


@pytest.mark.parametrize("argument", ["substeps", "solver_iterations"])
def test_counts_beyond_their_bound_are_value_errors(argument):
    raises(PENDULUM + f"lk.Simulation(model, {argument}=10**9)", "ValueError", argument)
    raises(PENDULUM + f"lk.Simulation(model, {argument}=2**70)", "ValueError", argument)


@pytest.mark.parametrize("dim", ["5", "-6", "2**70"])
@pytest.mark.parametrize("call", ["contact_dynamics(model, q, v, tau, [(1, [0, 0, 0])]", "impact_derivatives(model, q, v, [(1, [0, 0, 0])]"])
def test_a_contact_dim_other_than_3_or_6_is_a_value_error(call, dim):
    raises(PENDULUM + f"lk.{call}, dim={dim})", "ValueError", "dim: expected 3")


@pytest.mark.parametrize("n", ["-1", "2**70"])
def test_step_counts_out_of_range_are_value_errors(n):
    raises(PENDULUM + f"lk.Simulation(model).step(None, {n})", "ValueError", "n")
    raises(PENDULUM + f"lk.SimulationBatch([lk.Simulation(model)]).step(None, {n})", "ValueError", "n")


def test_arguments_of_the_wrong_type_are_type_errors_naming_them():
    raises(PENDULUM + 'lk.aba(model, "q", v, tau)', "TypeError", "q")
    raises(PENDULUM + "lk.Simulation(model).step(None, 1.5)", "TypeError", "n")
    raises(PENDULUM + "lk.free_rollout(model, q, v, 1e-3, 1e12)", "TypeError", "steps")


def test_a_simulation_stepped_from_two_threads_is_a_runtime_error():
    result = outcome(
        PENDULUM
        + """
import os, threading, time
sim = lk.Simulation(model)
threading.Thread(target=sim.step, args=(None, 10**12), daemon=True).start()
time.sleep(0.3)
messages = []
calls = (lambda: sim.step(), lambda: setattr(sim, "q", q), lambda: sim.reset(), lambda: sim.set_servo(1.0), lambda: sim.q,
         lambda: sim.time, lambda: sim.contacts(), lambda: sim.body_poses(), lambda: sim.transition_jacobians(), lambda: repr(sim))
for call in calls:
    try:
        call()
    except RuntimeError as error:
        messages.append(str(error))
report(raised="RuntimeError", messages=messages)
os._exit(0)
"""
    )
    assert len(result["messages"]) == 10 and all("another thread" in m for m in result["messages"]), result


# --- dependent contacts ----------------------------------------------------------------------------------------

QUADRUPED_FOOT = """
from legkit.robots.quadruped import build_quadruped
model = build_quadruped().model
q = model.neutral()
q[2] = 0.5
rng = np.random.default_rng(0)
v, tau = rng.normal(size=model.nv), rng.normal(size=model.nv)
foot = (model.nbodies - 1, [0.0, 0.0, -0.02])
"""


@pytest.mark.parametrize("dim", [3, 6])
@pytest.mark.parametrize(("function", "state"), [("contact_dynamics", "q, v, tau"), ("impact", "q, v")])
def test_a_repeated_contact_gets_the_minimum_norm_forces(function, state, dim):
    # A foot held twice moves as the foot held once, and the two copies share its force evenly: of the forces that
    # hold it, the split with the least norm (the forces of dependent contacts are not unique).
    result = outcome(
        QUADRUPED_FOOT
        + f"""
once = lk.{function}(model, {state}, [foot], dim={dim})
twice = lk.{function}(model, {state}, [foot, foot], dim={dim})
report(raised=None, motion=float(np.abs(twice[0] - once[0]).max()), split=float(np.abs(twice[1] - once[1] / 2).max()),
       force=float(np.abs(once[1]).max()))
"""
    )
    assert result["raised"] is None and result["force"] > 0.1, result
    assert result["motion"] <= 1e-9 and result["split"] <= 1e-9 * result["force"], result


@pytest.mark.parametrize("dim", [3, 6])
@pytest.mark.parametrize(("function", "state"), [("contact_dynamics_derivatives", "q, v, tau"), ("impact_derivatives", "q, v")])
def test_the_derivatives_of_dependent_contacts_are_a_value_error_naming_the_contact(function, state, dim):
    # Their forces are not unique, so neither are the derivatives: the message names the contact and the matrix,
    # where it once blamed the mass matrix.
    raises(
        QUADRUPED_FOOT + f"lk.{function}(model, {state}, [foot, foot], dim={dim})",
        "ValueError",
        "contacts: the contacts are not independent",
        f"row 1 of {dim} of contact 1 (body ",
        "contact Gram matrix J M⁻¹ Jᵀ is singular",
    )


# --- silent wrong answers --------------------------------------------------------------------------------------


@pytest.mark.parametrize("batch", [False, True])
def test_transition_jacobians_that_overflow_are_a_runtime_error(batch):
    # At v = 1e200 a double pendulum's Coriolis terms (v^2) overflow in A, which must not come back as NaN.
    result = outcome(
        PENDULUM
        + f"""
model.add_revolute(1, [0, 1, 0], placement=(np.eye(3), [0, 0, -1]), body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
sim = lk.Simulation(model)
sim.v = np.full(model.nv, 1e200)
before = (sim.q.tolist(), sim.v.tolist(), sim.time)
try:
    lk.SimulationBatch([sim]).transition_jacobians() if {batch} else sim.transition_jacobians()
except RuntimeError as error:
    report(raised="RuntimeError", message=str(error), unchanged=before == (sim.q.tolist(), sim.v.tolist(), sim.time))
"""
    )
    assert result["raised"] == "RuntimeError" and "not finite" in result["message"] and result["unchanged"], result


def test_a_tau_table_shaped_nv_by_steps_is_refused():
    model = lk.Model()
    first = model.add_revolute(0, [0, 1, 0], body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
    model.add_revolute(first, [0, 1, 0], placement=(np.eye(3), [0, 0, -1]), body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
    q, v = np.zeros(2), np.zeros(2)
    with pytest.raises(ValueError, match=r"tau: expected shape \(2,\) or \(5, 2\)"):
        lk.free_rollout(model, q, v, dt=1e-3, steps=5, tau=np.zeros((2, 5)))
    with pytest.raises(ValueError, match="tau"):
        lk.free_rollout(model, q, v, dt=1e-3, steps=5, tau=np.zeros(10))
    table = np.arange(10.0).reshape(5, 2)
    qs, _ = lk.free_rollout(model, q, v, dt=1e-3, steps=5, tau=table)
    assert qs.shape == (6, 2)


@pytest.mark.parametrize(
    "call",
    [
        "lk.rnea(model, q, np.full(1, 1e200), tau)",
        "lk.aba(model, q, np.full(1, 1e200), tau)",
        "lk.integrate(model, q, np.full(1, 1e308), 10.0)",
        "lk.kinetic_energy(model, q, np.full(1, 1e200))",
        "lk.free_rollout(model, q, np.full(1, 1e200), dt=1e-3, steps=3)",
        "lk.centroidal_momentum_rate(model, q, np.full(1, 1e200), tau)",
        "lk.center_of_mass(model.with_body(1, lk.MassProperties.point(1e300, [0, 0, 1e200])), q)",
        "lk.crba(model.with_body(1, lk.MassProperties.point(1e300, [0, 0, 1e200])), q)",
    ],
)
def test_a_result_that_overflows_is_a_runtime_error_not_a_singular_matrix(call):
    exec(PENDULUM, namespace := {"lk": lk, "np": np})
    with pytest.raises(RuntimeError, match="overflow") as error:
        eval(call, namespace)
    assert "singular" not in str(error.value)


@pytest.mark.parametrize(
    "call",
    [
        "lk.rnea_derivatives(double, q, v, a)",
        "lk.rnea_second_order_derivatives(double, q, v, a)",
        "lk.centroidal_derivatives(double, q, v, a)",
        "lk.point_accelerations(double, q, v, a, [(2, [0, 0, -1.0])])",
        "lk.integrate_jacobians(free, q_free, np.full(6, 1e308), 10.0)",
        "lk.reduced_dynamics(free, q_free, np.full(6, 1e200), np.zeros(6), [(0, [0, 0, -1.0])])",
    ],
)
def test_derivatives_and_contact_kinematics_that_overflow_are_runtime_errors_not_nan(call):
    # A double pendulum's and an offset free body's v^2 terms overflow at v = 1e200: these returned NaN or inf silently.
    double = lk.Model()
    first = double.add_revolute(0, [0, 1, 0], body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
    double.add_revolute(first, [0, 1, 0], placement=(np.eye(3), [0, 0, -1]), body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
    free = lk.Model(floating_base=True, base=lk.MassProperties(1.0, [0, 0, 0.1], np.eye(3) * 0.01))
    namespace = {"lk": lk, "np": np, "double": double, "free": free, "q": np.zeros(2), "v": np.full(2, 1e200), "a": np.zeros(2),
                 "q_free": np.r_[0, 0, 0, 0, 0, 0, 1.0]}
    with pytest.raises(RuntimeError, match="result: not finite: a number overflowed"):
        eval(call, namespace)
    at_rest = call.replace("np.full(2, 1e200)", "np.zeros(2)").replace("v, a", "np.zeros(2), a").replace("1e308", "1.0").replace("1e200", "1.0")
    outputs = eval(at_rest, namespace)  # the same call at physical magnitudes is finite
    assert all(np.all(np.isfinite(np.asarray(x, dtype=float))) for x in (outputs if isinstance(outputs, tuple) else (outputs,))
               if not isinstance(x, list))


@pytest.mark.parametrize(
    "call",
    [
        "a + a",
        "a.transformed(np.eye(3), [1e200, 0, 0])",
        "a.inertia_about([1e200, 0, 0])",
        "lk.MassProperties.from_points([1e308, 1e308], np.zeros((2, 3)))",
    ],
)
def test_mass_algebra_that_overflows_is_a_runtime_error(call):
    namespace = {"lk": lk, "np": np, "a": lk.MassProperties(1e300, [0, 0, 0], np.eye(3) * 1e308)}
    with pytest.raises(RuntimeError, match="overflow"):
        eval(call, namespace)


@pytest.mark.parametrize("floating", [False, True])
@pytest.mark.parametrize("call", ["lk.aba(model, q, v, tau)", "lk.minv(model, q)", "lk.free_rollout(model, q, v, 1e-3, 3)"])
def test_a_singular_mass_matrix_is_a_runtime_error_everywhere(call, floating):
    # A massless link on a fixed base; a massless floating base whose one link turns about its own centre, so
    # the base's articulated inertia loses that rotation while every joint's pivot stays positive.
    model = lk.Model(floating_base=floating)
    model.add_revolute(0, [0, 0, 1], body=lk.MassProperties(1.0, [0, 0, 0], 0.1 * np.eye(3)) if floating else lk.MassProperties.zero())
    q, v = model.neutral(), np.zeros(model.nv)
    namespace = {"lk": lk, "model": model, "q": q, "v": v, "tau": v}
    with pytest.raises(RuntimeError, match="singular"):
        eval(call, namespace)


# --- a failed step changes nothing -------------------------------------------------------------------------------


def _state(sim: lk.Simulation) -> list:
    contacts = sim.contacts()
    return [sim.q, sim.v, np.array([sim.time]), sim.applied_tau] + [contacts[key] for key in sorted(contacts)]


def _go1() -> lk.Model:
    import warnings
    from importlib.metadata import distribution

    robots = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", lk.UrdfWarning)
        return lk.Model.from_urdf(robots / "go1_description/urdf/go1.urdf", floating_base=True)


@pytest.mark.parametrize(
    ("backend", "scene"),
    [("tree", "plane"), ("rapier", "plane"), ("tree", "heightfield"), ("rapier", "heightfield"), ("tree", "go1 self-collision")],
)
def test_a_step_that_raises_leaves_the_simulation_as_a_never_failed_twin(backend, scene):
    from legkit.robots.quadruped import build_quadruped

    # On the heightfield and between Go1's bodies the contacts go through parry's manifolds.
    bumps = 0.01 * np.sin(np.arange(30))[:, None] * np.cos(np.arange(30))[None, :]
    ground = lk.Ground.heightfield(bumps, 0.1, friction=0.8) if scene == "heightfield" else lk.Ground.plane(friction=0.8)
    model = _go1() if scene.startswith("go1") else build_quadruped().model
    sims = [lk.Simulation(model, dt=1e-3, ground=ground, backend=backend, self_collision=scene.startswith("go1")) for _ in range(2)]
    start = model.neutral()
    start[2] = 0.35 if scene.startswith("go1") else start[2]
    for sim in sims:
        sim.reset(start, np.zeros(model.nv))
    for sim in sims:
        sim.step(None, 500)  # on the ground (Go1 collapsed on its limp legs): contacts and warm starts in play
    assert len(sims[0].contacts()["body"]) > 0
    before = _state(sims[0])
    huge = np.full(model.nv, 1e11)  # within the actuation bound (the base's wrench is not effort-limited), but it explodes
    with pytest.raises(RuntimeError, match="diverged"):
        sims[0].step(huge, 1)
    for a, b in zip(before, _state(sims[0]), strict=True):
        assert np.array_equal(a, b)
    for sim in sims:
        sim.step(None, 300)
    for a, b in zip(_state(sims[0]), _state(sims[1]), strict=True):
        assert np.array_equal(a, b)


# --- interruptible long calls ----------------------------------------------------------------------------------

LONG_CALLS = {  # setup, call
    "step": ("sim = lk.Simulation(model, ground=lk.Ground.plane())", "sim.step(None, 10**12)"),
    "batch": ("batch = lk.SimulationBatch([lk.Simulation(model, ground=lk.Ground.plane())])", "batch.step(None, 10**12)"),
    # 10**7 steps: a 3 GB output, whose zeros were written before the first step (3 s of CPU deaf to Ctrl-C).
    "rollout": ("", "lk.free_rollout(model, model.neutral(), np.zeros(model.nv), 1e-3, 10**7)"),
}


CPU_SECONDS = """
import os
def cpu_seconds():
    # Each thread's CPU time (s), by thread id: what /proc says, as the parent reads it at the signal.
    seconds = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            fields = open(f"/proc/self/task/{tid}/stat").read().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended meanwhile
            continue
        seconds[tid] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return seconds

def thread_names():
    return [open(f"/proc/self/task/{tid}/comm").read().strip() for tid in os.listdir("/proc/self/task")]

def answer():
    report(raised="KeyboardInterrupt", cpu=cpu_seconds(), threads=thread_names())
"""


def threads_cpu_seconds(pid: int) -> dict[str, float]:
    """The CPU time (s) of each thread of process `pid`, by thread id (the child's `cpu_seconds`)."""
    namespace: dict = {}
    exec(CPU_SECONDS.replace("/proc/self/", f"/proc/{pid}/"), namespace)
    return namespace["cpu_seconds"]()


def interrupted_child(body: str, *, memory: int, after: float, timeout: float,
                      at_signal: Callable[[int], Any] = lambda pid: None, cpu_paced: bool = False) -> tuple[dict, Any]:
    """Runs `body` in a child (inside PRELUDE, under a `memory`-byte limit); the body prints `STARTED whole` before
    its interruptible call and reports how it ended. SIGINTs the child `after` times `whole` seconds after that line
    (cpu_paced: once its threads have worked that many CPU seconds since, so that a loaded machine, on which the
    child gets less than a core, does not move the signal to an earlier point of its work), and expects
    KeyboardInterrupt. Returns the child's report and what `at_signal(pid)` returned just before the signal."""
    code = PRELUDE.format(memory=memory, body=textwrap.indent(body, "    "))
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=ctrl_c_restored)
    try:
        assert child.stdout is not None
        started, whole = child.stdout.readline().split()
        assert started == "STARTED"
        if cpu_paced:
            # Each live thread's CPU since that line: a thread that ends meanwhile (the last call's worker) leaves the sum.
            base, deadline = threads_cpu_seconds(child.pid), time.monotonic() + timeout

            def worked() -> float:
                return sum(cpu - base.get(tid, 0.0) for tid, cpu in threads_cpu_seconds(child.pid).items())

            while worked() < after * float(whole) and child.poll() is None and time.monotonic() < deadline:
                time.sleep(0.005)
        else:
            time.sleep(after * float(whole))
        before_signal = at_signal(child.pid)
        child.send_signal(signal.SIGINT)
        out, err = child.communicate(timeout=timeout)
    finally:
        child.kill()
    results = [line for line in out.splitlines() if line.startswith("RESULT ")]
    assert results, err[-2000:]
    result = json.loads(results[0].removeprefix("RESULT "))
    assert result["raised"] == "KeyboardInterrupt", (result, err[-2000:])
    return result, before_signal


def assert_ctrl_c_answered_within_a_second(setup: str, call: str, *, after: float, memory: int) -> dict:
    """Runs `setup` in a child, then `call`, SIGINT `after` s into it (`after` times `whole` if `setup` sets
    `whole`, the call's duration as timed in the child), and expects KeyboardInterrupt to end the
    call within a second of work: no thread of the child may run for more than a second of CPU time between
    the signal and the answer. CPU time, not wall time, so that a loaded machine (which delays the answer
    but not the work done before it) cannot fail the test, and a call that ignores Ctrl-C, whose threads
    work on, still does. Returns the child's report, with the names of the threads alive at the answer."""
    started = "print('STARTED', globals().get('whole', 1.0), flush=True)"
    body = f"{CPU_SECONDS}\n{setup}\n{started}\ntry:\n    {call}\nexcept KeyboardInterrupt:\n    answer()"
    result, at_signal = interrupted_child(body, memory=memory, after=after, timeout=60, at_signal=threads_cpu_seconds)
    worked = {tid: cpu - at_signal.get(tid, 0.0) for tid, cpu in result["cpu"].items()}
    assert max(worked.values()) < 1.0, worked
    return result


def test_ctrl_c_interrupts_a_long_batched_kernel_within_a_second(tmp_path):
    # 30,000 states of a 300-link chain in contact (about 10 s).
    (tmp_path / "chain.urdf").write_text(chain_urdf(300))
    setup = f"model = lk.Model.from_urdf({str(tmp_path / 'chain.urdf')!r})\nq = np.zeros((30_000, model.nq))"
    call = "lk.contact_dynamics(model, q, q, q, [(model.nbodies - 1, [0, 0, 0])])"
    assert_ctrl_c_answered_within_a_second(setup, call, after=0.5, memory=4 * GIB)


@pytest.mark.parametrize("call", sorted(LONG_CALLS))
def test_ctrl_c_interrupts_a_long_call_within_a_second(call):
    setup, long_call = LONG_CALLS[call]
    setup = f"from legkit.robots.quadruped import build_quadruped\nmodel = build_quadruped().model\n{setup}"
    assert_ctrl_c_answered_within_a_second(setup, long_call, after=0.5, memory=4 * GIB)


def test_ctrl_c_interrupts_the_balance_kernel_agreeing_on_a_long_chain_within_a_second():
    # 20,000 modules in a chain: a round takes about 12 ms, and signals were checked every 1024 rounds.
    setup = (
        "from legkit.agents import AgentNetwork\nfrom legkit.control import BalanceController, BalanceKernel, GainSchedule\n"
        "from legkit.robots import Connection, ModuleTree\n"
        "chain = [Connection(0, 1, 1, 0)] + [Connection(i, 3, i + 1, 0) for i in range(1, 19_999)]\n"
        "kernel = BalanceKernel(BalanceController(AgentNetwork([ModuleTree(20_000, chain)]), GainSchedule()))"
    )
    assert_ctrl_c_answered_within_a_second(setup, "kernel.run_until_quiescent()", after=4.0, memory=4 * GIB)


def test_ctrl_c_interrupts_a_gait_optimisation_within_a_second():
    # casadi checks for signals between IPOPT's steps and, finding Ctrl-C, ended the solve as failed and dropped the
    # KeyboardInterrupt: the plan went on to its next stage, and Ctrl-C was ignored until the last.
    setup = (
        "from legkit.gaits.references import AMBLE_QUADRUPED\nfrom legkit.optimize.gaits import plan_amble\n"
        "from legkit.robots.quadruped import build_quadruped\nrobot = build_quadruped(AMBLE_QUADRUPED)"
    )
    assert_ctrl_c_answered_within_a_second(setup, "plan_amble(robot)", after=6.0, memory=4 * GIB)


@pytest.mark.parametrize("batch", [False, True])
def test_ctrl_c_interrupts_transition_jacobians_of_many_substeps_and_changes_nothing(tmp_path, batch):
    # A thousand substeps of a 60-link chain take about 3 s a simulation, which ran to their end before; stopped,
    # the call leaves every simulation as it was: the next step is the never-interrupted twin's.
    (tmp_path / "chain.urdf").write_text(chain_urdf(60))
    setup = f"""
model = lk.Model.from_urdf({str(tmp_path / "chain.urdf")!r})
sims = [lk.Simulation(model, substeps=1000) for _ in range(3)]
for sim in sims:
    sim.step(None, 2)
def state(sim):
    return [sim.q.tolist(), sim.v.tolist(), sim.time, sim.applied_tau.tolist()]
before = [state(sim) for sim in sims]
uninterrupted = lk.Simulation(model, substeps=1000)
uninterrupted.step(None, 3)
first_report = report
def report(**fields):
    unchanged = [state(sim) for sim in sims] == before
    sims[0].step(None, 1)
    first_report(unchanged=unchanged, twin=state(sims[0]) == state(uninterrupted), **fields)
"""
    call = "lk.SimulationBatch(sims).transition_jacobians()" if batch else "sims[0].transition_jacobians()"
    result = assert_ctrl_c_answered_within_a_second(setup, call, after=0.5, memory=4 * GIB)
    assert result["unchanged"] and result["twin"], result


def test_ctrl_c_interrupts_one_long_substep_of_transition_jacobians(tmp_path):
    # One substep of a 1000-link chain takes about 2.6 s (a pair of contact passes per coordinate); its first call,
    # of a length not yet timed, is stopped too.
    (tmp_path / "chain.urdf").write_text(chain_urdf(1000))
    setup = f"""
model = lk.Model.from_urdf({str(tmp_path / "chain.urdf")!r})
sim = lk.Simulation(model)
sim.step(None, 2)
q = sim.q.copy()
def fresh():
    global sim
    sim = lk.Simulation(model)
    sim.step(None, 2)
"""
    result = assert_ctrl_c_answered_within_a_second(setup, "fresh(); sim.transition_jacobians()", after=0.5, memory=4 * GIB)
    assert result["raised"] == "KeyboardInterrupt"


@pytest.mark.slow
def test_ctrl_c_interrupts_loading_a_huge_urdf(tmp_path):
    path = tmp_path / "chain.urdf"
    path.write_text(chain_urdf(500_000))
    assert_ctrl_c_answered_within_a_second("", f"lk.Model.from_urdf({str(path)!r})", after=1.0, memory=8 * GIB)


@pytest.mark.slow
def test_ctrl_c_during_the_xml_parse_is_answered_before_the_parse_ends():
    # The parse is one call that cannot be cut: the loader's worker thread parses on, and the caller answers
    # Ctrl-C without waiting for it (the worker frees what it parsed when it ends). Elements of 1024 attributes
    # (the most allowed) make the parse nearly the whole load (about 3 s) in little memory.
    element = "<a " + " ".join(f'b{i}="0"' for i in range(1024)) + "/>"
    setup = f"""
import time
urdf = '<robot name="r"><link name="base"/><documentation>' + {element!r} * 3000 + '</documentation></robot>'
started = time.monotonic()
lk.Model.from_urdf(urdf)
whole = time.monotonic() - started
"""
    result = assert_ctrl_c_answered_within_a_second(setup, "lk.Model.from_urdf(urdf)", after=0.4, memory=4 * GIB)
    assert "from_urdf" in result["threads"], result  # still parsing: the answer did not wait for it


def flat_mjcf(bodies: int) -> str:
    """An MJCF world of `bodies` free-standing bodies, each on a hinge with a sphere."""
    body = '<body pos="0 0 1"><joint type="hinge"/><geom size="0.1"/></body>'
    return "<mujoco><worldbody>" + body * bodies + "</worldbody></mujoco>"


def interrupted_load(path: Path, kind: str, whole: float | None = None) -> dict:
    """Loads `path` (a URDF or MJCF file) in a child once to time it (T), then again, interrupted halfway through
    that second load (once the child has worked T / 2 CPU seconds on it); the child reports T (`whole`, CPU
    seconds) and the CPU seconds its worker thread (named from_urdf or from_mjcf) ran after the interrupt, until it
    ended (`worker_cpu_after`). CPU seconds, not wall time, so that a loaded machine does not stretch what is
    measured. A load too long to time is given its `whole` (CPU s) instead: it is interrupted once, at half that."""
    body = f"""
import os, time
TICK = os.sysconf("SC_CLK_TCK")
def worker_cpu():  # CPU seconds of the from_urdf worker threads alive now
    total = 0.0
    for t in os.listdir("/proc/self/task"):
        try:
            if open(f"/proc/self/task/{{t}}/comm").read().strip() == "from_{kind}":
                fields = open(f"/proc/self/task/{{t}}/stat").read().rsplit(")", 1)[1].split()
                total += (int(fields[11]) + int(fields[12])) / TICK
        except OSError:  # the thread ended meanwhile (ENOENT or ESRCH)
            pass
    return total
started_cpu = time.process_time()
{f"lk.Model.from_{kind}({str(path)!r})" if whole is None else ""}
whole = {"time.process_time() - started_cpu" if whole is None else whole}  # CPU seconds: the worker's work, whatever else runs
print("STARTED", whole, flush=True)
try:
    lk.Model.from_{kind}({str(path)!r})
except KeyboardInterrupt:
    interrupted, at_interrupt, last = time.monotonic(), worker_cpu(), 0.0
    while time.monotonic() - interrupted < 60:
        now = worker_cpu()
        if now == 0.0:
            break
        last = now
        time.sleep(0.005)
    report(raised="KeyboardInterrupt", whole=whole, worker_cpu_after=max(last - at_interrupt, 0.0))
"""
    return interrupted_child(body.strip(), memory=8 * GIB, after=0.5, timeout=120, cpu_paced=True)[0]


@pytest.mark.slow
@pytest.mark.serial
@pytest.mark.parametrize(("kind", "document"), [("urdf", chain_urdf), ("mjcf", flat_mjcf)])
def test_an_interrupted_load_stops_its_worker_thread(tmp_path, kind, document):
    # A 500,000-link model: interrupted halfway, the worker thread is cancelled and ends, instead of loading on in
    # the background for the other half. (The XML parse itself is one call that cannot be cut: it is over by then.)
    path = tmp_path / f"model.{kind}"
    path.write_text(document(500_000))
    result = interrupted_load(path, kind)
    assert result["worker_cpu_after"] < 0.25 * result["whole"], result


@pytest.mark.slow
@pytest.mark.serial
@pytest.mark.parametrize("kind", ["urdf", "mjcf"])
def test_an_interrupted_load_of_a_mesh_with_a_huge_hull_stops_within_a_second(tmp_path, kind):
    # 900,000 vertices on a sphere, all on its hull: parry took 52 s of CPU over them in one call that cannot be
    # cut, and went on for as long after Ctrl-C. Its hull is now taken over at most 25,000 of them (a warning says
    # so), and the reading and thinning before it are interruptible.
    binary_stl(tmp_path / "sphere.stl", 300_000, sphere=True)
    path = tmp_path / f"model.{kind}"
    path.write_text(mesh_model(kind, "sphere.stl"))
    result = interrupted_load(path, kind)
    assert result["worker_cpu_after"] < 1.0, result


def mesh_model(kind: str, mesh: str) -> str:
    """A URDF or MJCF document of one body colliding as the mesh file `mesh`."""
    if kind == "urdf":
        return chain_urdf(1).replace('<link name="l0">', f'<link name="l0"><collision><geometry><mesh filename="{mesh}"/></geometry></collision>')
    body = '<body><freejoint/><geom type="mesh" mesh="m"/></body>'
    return f'<mujoco><asset><mesh name="m" file="{mesh}"/></asset><worldbody>{body}</worldbody></mujoco>'


def test_a_mesh_beyond_the_hull_bound_is_thinned_with_a_warning(tmp_path):
    binary_stl(tmp_path / "sphere.stl", 100_000, sphere=True)
    with pytest.warns(lk.UrdfWarning, match=r"its convex hull is taken over \d+ of its 300000 distinct vertices \(each within"):
        model = lk.Model.from_urdf(mesh_model("urdf", str(tmp_path / "sphere.stl")))
    ((_, kind, vertices, _),) = model.colliders()
    assert kind == "convex"
    assert 10_000 < len(vertices) <= 25_000
    # The thinned hull lies inside the unit sphere and reaches it in every direction, to within the grid's cell.
    assert np.all(np.linalg.norm(vertices, axis=1) <= 1 + 1e-6)
    directions = np.random.default_rng(1).normal(size=(1000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    assert np.all((directions @ np.asarray(vertices).T).max(axis=1) > 0.95)
    with pytest.raises(ValueError, match="convex hull is taken over"):
        lk.Model.from_mjcf(mesh_model("mjcf", str(tmp_path / "sphere.stl")), strict=True)


def test_a_mesh_whose_triangles_share_corners_keeps_its_whole_hull(tmp_path):
    # An STL lists each triangle's corners: a 12,000-triangle sphere has 36,000 of them but 5,942 distinct points,
    # which the hull takes whole, without a warning (counting the repeats, it was thinned with one, and refused
    # under strict=True).
    lat, lon = 60, 100
    theta, phi = np.meshgrid(np.linspace(0.0, np.pi, lat + 1), np.linspace(0.0, 2.0 * np.pi, lon + 1), indexing="ij")
    grid = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
    a, b, c, d = grid[:-1, :-1], grid[1:, :-1], grid[1:, 1:], grid[:-1, 1:]
    corners = np.concatenate([np.stack([a, b, c], axis=2), np.stack([a, c, d], axis=2)]).reshape(-1, 3, 3)
    records = np.zeros(len(corners), dtype=[("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
    records["vertices"] = corners
    (tmp_path / "sphere.stl").write_bytes(b"\0" * 80 + np.uint32(len(corners)).tobytes() + records.tobytes())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = lk.Model.from_urdf(mesh_model("urdf", str(tmp_path / "sphere.stl")), strict=True)
    ((_, kind, vertices, _),) = model.colliders()
    distinct = np.unique(records["vertices"].reshape(-1, 3).astype(np.float64), axis=0)
    assert kind == "convex" and len(corners) * 3 > 25_000 >= len(distinct)
    # The hull's vertices are the sphere's distinct points on it: all but the poles' repeats, none thinned away.
    assert {tuple(v) for v in np.asarray(vertices)} <= {tuple(p) for p in distinct}
    assert len(vertices) > 0.9 * len(distinct)


def test_an_interrupted_step_keeps_whole_steps():
    model = lk.Model()
    model.add_revolute(0, [0, 1, 0], body=lk.MassProperties.point(1.0, [0, 0, -0.5]))
    sim, twin = lk.Simulation(model), lk.Simulation(model)
    signal.setitimer(signal.ITIMER_REAL, 0.2)
    previous = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(KeyboardInterrupt))
    try:
        with pytest.raises(KeyboardInterrupt):
            sim.step(None, 10**12)
    finally:
        signal.signal(signal.SIGALRM, previous)
    steps = round(sim.time / sim.dt)
    assert steps > 0 and sim.time == steps * sim.dt
    twin.step(None, steps)
    assert np.array_equal(sim.q, twin.q) and np.array_equal(sim.v, twin.v)


# --- loading -------------------------------------------------------------------------------------------------


def test_loading_a_chain_takes_time_linear_in_its_links(tmp_path):
    # Ten times the links, about ten times the CPU time (the loader's worker thread counts in process_time); a name
    # scan or an ancestor walk per link made it a hundred times (a 10^5-link chain took 64 s). The absolute figure
    # (10^5 links: 0.7 s) is a benchmark's (benches/), not a test's.
    seconds = {}
    for links in (10_000, 100_000):
        path = tmp_path / f"chain{links}.urdf"
        path.write_text(chain_urdf(links))
        started = time.process_time()
        model = lk.Model.from_urdf(str(path))
        seconds[links] = time.process_time() - started
        assert model.nbodies == links
    assert seconds[100_000] < 30.0 * seconds[10_000], seconds


def test_an_element_with_150000_attributes_is_refused_at_once():
    # The XML parser's time grows with the square of one element's attributes (> 15 s here): refused first.
    attributes = " ".join(f'a{i}="0"' for i in range(150_000))
    urdf = f'<robot name="r"><link name="base" {attributes}/></robot>'
    started = time.process_time()
    with pytest.raises(ValueError, match="more than 1024 attributes"):
        lk.Model.from_urdf(urdf)
    assert time.process_time() - started < 1.0  # CPU time: parsing first took more than 15 s


def test_a_urdf_string_with_a_byte_order_mark_is_xml():
    model = lk.Model.from_urdf('\ufeff<robot name="r"><link name="base"/></robot>')
    assert model.nbodies == 1


# --- paths ---------------------------------------------------------------------------------------------------


def test_a_fifo_is_refused_before_it_is_opened(tmp_path):
    fifo = tmp_path / "robot.urdf"
    os.mkfifo(fifo)
    raises(f"lk.Model.from_urdf({str(fifo)!r})", "ValueError", "path", "not a regular file", timeout=10)


def test_a_mesh_found_nowhere_is_a_file_not_found_error(tmp_path):
    raises(f"lk.resolve_mesh('package://nowhere/x.stl', package_dirs=[{str(tmp_path)!r}])", "FileNotFoundError", "package_dirs")


def test_a_package_name_cannot_escape_its_package(tmp_path):
    (tmp_path / "secret.stl").write_text("solid s\nendsolid s\n")
    package = tmp_path / "share" / "bot"
    package.mkdir(parents=True)
    with pytest.raises(ValueError, match="filename.*outside"):
        lk.resolve_mesh("package://bot/../../secret.stl", package_dirs=[str(tmp_path / "share")])


CUBE_STL = (
    "solid s\n"
    + "".join(
        f"facet normal 0 0 0\nouter loop\nvertex {x} {y} {z}\nvertex {x} {y} 0\nvertex 0 0 {z}\nendloop\nendfacet\n"
        for x in (0, 1)
        for y in (0, 1)
        for z in (0, 1)
    )
    + "endsolid s\n"
)

MESH_URDF = """<robot name="bot"><link name="base"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/>
  </inertial><collision><geometry><mesh filename="{filename}"/></geometry></collision></link></robot>"""


def test_a_symbolic_link_out_of_its_package_must_reach_a_mesh(tmp_path):
    # A package unpacked from an archive may bring links of its own: one that leads out of the package is
    # followed only to a file of the name's kind, never to a key that the viewer would embed in its HTML.
    (tmp_path / "id_rsa").write_text("not a mesh")
    (tmp_path / "elsewhere.stl").write_text(CUBE_STL)
    share = tmp_path / "share"
    meshes = share / "bot" / "meshes"
    meshes.mkdir(parents=True)
    (meshes / "leg.stl").symlink_to(tmp_path / "id_rsa")
    (meshes / "foot.stl").symlink_to(tmp_path / "elsewhere.stl")
    (meshes / "copy.stl").write_text(CUBE_STL)
    (meshes / "alias.stl").symlink_to(meshes / "copy.stl")
    (share / "bot" / "outside").symlink_to(tmp_path)
    for name in ["package://bot/meshes/leg.stl", "model://bot/outside/id_rsa"]:
        with pytest.raises(ValueError, match="filename.*outside its package .* to a file of another kind"):
            lk.resolve_mesh(name, package_dirs=[share])
    assert lk.resolve_mesh("package://bot/meshes/alias.stl", package_dirs=[share]) == meshes / "alias.stl"
    assert lk.resolve_mesh("package://bot/meshes/foot.stl", package_dirs=[share]) == meshes / "foot.stl"
    assert lk.resolve_mesh("package:///bot/outside/elsewhere.stl", package_dirs=[share]) == share / "bot" / "outside" / "elsewhere.stl"
    # Loading: the link collides as the box of its inertia, with a warning that says why.
    with pytest.warns(lk.UrdfWarning, match="another kind"):
        model = lk.Model.from_urdf(MESH_URDF.format(filename="package://bot/meshes/leg.stl"), package_dirs=[str(share)])
    assert [kind for _, kind, _, _ in model.colliders()] == ["box"]


def colcon_workspace(root: Path) -> Path:
    """A colcon workspace built with --symlink-install: src/bot holds the package, install/bot/share/bot links
    each of its files there. Returns the installed URDF."""
    source = root / "src" / "bot"
    (source / "meshes").mkdir(parents=True)
    (source / "urdf").mkdir()
    (source / "meshes" / "leg.stl").write_text(CUBE_STL)
    (source / "urdf" / "bot.urdf").write_text(MESH_URDF.format(filename="package://bot/meshes/leg.stl"))
    installed = root / "install" / "bot" / "share" / "bot"
    for relative in ["meshes/leg.stl", "urdf/bot.urdf"]:
        (installed / relative).parent.mkdir(parents=True, exist_ok=True)
        (installed / relative).symlink_to(source / relative)
    return installed / "urdf" / "bot.urdf"


def test_a_colcon_symlink_install_workspace_loads_as_pinocchio_loads_it(tmp_path, monkeypatch):
    import pinocchio as pin

    urdf = colcon_workspace(tmp_path)
    share = tmp_path / "install" / "bot" / "share"
    installed_mesh = share / "bot" / "meshes" / "leg.stl"
    pin_model = pin.buildModelFromUrdf(str(urdf))
    pin_geometry = pin.buildGeomFromUrdf(pin_model, str(urdf), pin.COLLISION, package_dirs=[str(share)])
    assert Path(pin_geometry.geometryObjects[0].meshPath).resolve() == installed_mesh.resolve()
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    # Through package_dirs, the URDF's folder's ancestors, and a sourced workspace's AMENT_PREFIX_PATH.
    assert lk.resolve_mesh("package://bot/meshes/leg.stl", package_dirs=[share]) == installed_mesh
    assert lk.resolve_mesh("package://bot/meshes/leg.stl", urdf) == installed_mesh
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install" / "bot"))
    assert lk.resolve_mesh("package://bot/meshes/leg.stl") == installed_mesh
    with warnings.catch_warnings():
        warnings.simplefilter("error", lk.UrdfWarning)
        for model in [lk.Model.from_urdf(urdf), lk.Model.from_urdf(urdf.read_text())]:
            assert [kind for _, kind, _, _ in model.colliders()] == ["convex"]
    # A name still cannot climb out of the package, symlinked or not.
    with pytest.raises(ValueError, match="filename.*outside its package"):
        lk.resolve_mesh("package://bot/../../../src/bot/meshes/leg.stl", urdf)


# --- Python entry points ---------------------------------------------------------------------------------------

IK = "from legkit.robots.legs import roll_pitch_knee_ik\n"
NETWORK = "from legkit.agents import AgentNetwork\nfrom legkit.robots import random_tree\nnetwork = AgentNetwork(random_tree(5))\n"


@pytest.mark.parametrize(
    ("call", "expected", "name"),
    [
        # NaN feet and zero-length legs came back as NaN angles.
        (IK + "roll_pitch_knee_ik([np.nan, 0.0, -0.3], 0.2, 0.2, 1.0)", "ValueError", "foot"),
        (IK + "roll_pitch_knee_ik([0.0, 0.0, 0.0], 0.0, 0.0, 1.0)", "ValueError", "upper"),
        (IK + "roll_pitch_knee_ik([0.0, 0.0, -0.3], 0.2, 0.2, 0.0)", "ValueError", "knee_direction"),
        # NumPy's "expected non-negative integer", naming nothing.
        ("from legkit.robots import random_tree\nrandom_tree(5, seed=-1)", "ValueError", "seed"),
        # A negative count ran no round without a word, or said the network did not fall silent.
        (NETWORK + "network.run(-1)", "ValueError", "rounds"),
        (NETWORK + "network.run(np.nan)", "TypeError", "rounds"),
        (NETWORK + "network.run_until_quiescent(-5)", "ValueError", "max_rounds"),
    ],
)
def test_python_entry_points_refuse_non_finite_values_and_negative_counts_by_name(call, expected, name):
    result = raises(call, expected)
    assert result["message"].startswith(name), result


# --- the commands ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ["balance", "--out", "{file}/out"],
        ["strain", "--out", "{file}/out"],
        ["gait", "--out", "{file}/out"],
        ["balance", "--trees", "10**12"],
        ["balance", "--trees", "1000000000000"],
        ["sweep", "--seeds", "1" * 5000],
        ["strain", "--seed", "-1"],
        ["balance", "--seed", "-1"],
        ["tune", "--seed", "-1"],
        ["gait", "--tol", "nan", "--optimize"],  # ran IPOPT with a NaN tolerance
        ["gait", "--tol", "0", "--optimize"],  # casadi's traceback: invalid IPOPT options
        ["gait", "--replay-kp", "nan", "--optimize"],
        ["gait", "--max-impulse", "-1", "--optimize"],  # the library's traceback
        ["gait", "--torque-margin", "1", "--optimize"],
    ],
)
def test_a_command_refuses_an_unwritable_out_or_a_huge_count_before_it_runs(tmp_path, capsys, argv):
    from legkit.cli import main

    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit) as exit:
        main([a.format(file=tmp_path / "file") for a in argv])
    assert exit.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert error.startswith(f"legkit {argv[0]}: error: argument {argv[1]}: "), error


@pytest.mark.parametrize(
    "argv, given",
    [(["--robot", "biped", "--biped-step", "10"], "--biped-speed/--biped-step"),
     (["--robot", "quadruped", "--quadruped-speed", "1e6"], "--quadruped-speed/--quadruped-period")],
)
def test_gait_refuses_a_step_the_legs_cannot_reach_naming_the_arguments(tmp_path, capsys, argv, given):
    from legkit.cli import main

    with pytest.raises(SystemExit) as exit:
        main(["gait", "--out", str(tmp_path), *argv])
    assert exit.value.code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert error.startswith(f"legkit gait: error: {given}: foot target out of reach"), error


@pytest.mark.parametrize(
    "argv, message",
    [
        (["gait", "--biped-intervals", "1000000", "--optimize"], "--biped-intervals must be at most 1000"),  # a traceback
        (["gait", "--min-normal-force", "1e308", "--optimize", "--robot", "quadruped"], "min_normal_force must be in [0, 100 x"),  # overflow
        (["strain", "--duration", "1e-9"], "duration 1e-09 s is shorter than one sample"),  # a traceback
    ],
)
def test_a_value_the_library_refuses_is_one_line_naming_it(tmp_path, capsys, argv, message):
    from legkit.cli import main

    try:
        code = main([*argv, "--out", str(tmp_path / "out")])
    except SystemExit as exit:  # argparse's error
        code = exit.code
    assert code == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert error.startswith(f"legkit {argv[0]}: error: ") and message in error, error


def test_a_sweep_without_its_spec_file_says_so_in_one_line(tmp_path, capsys):
    from legkit.cli import main

    assert main(["sweep", "--spec", str(tmp_path / "missing.json")]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("legkit sweep: --spec: cannot read") and len(error.splitlines()) == 1, error
