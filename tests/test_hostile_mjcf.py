"""Hostile MJCF `<replicate>` elements: counts MuJoCo refuses, counts that ask for more than memory holds (alone or
nested), and Ctrl-C while the copies are made. Each case that could exhaust memory or run long runs in a child
process with a timeout and a memory limit (`test_hostile.outcome`); what MuJoCo compiles is compared with MuJoCo.
"""

from __future__ import annotations

import mujoco
import pytest

import legkit as lk
from test_hostile import interrupted_load, raises

BODY = '<body name="b"><joint/><geom size=".1"/></body>'


def replicate(count: str, inner: str = BODY) -> str:
    return f'<mujoco><worldbody><replicate count="{count}" offset="1 0 0">{inner}</replicate></worldbody></mujoco>'


@pytest.mark.parametrize("count", ["2.5", "x", "3 4", "1e3", "", "99999999999999999999"])
def test_a_count_mujoco_refuses_is_a_value_error_naming_count(count):
    xml = replicate(count).replace(' count=""', "")
    with pytest.raises(ValueError, match="count"):
        mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(ValueError, match="count") as refused:
        lk.Model.from_mjcf(xml)
    assert "<replicate> (<string>:1)" in str(refused.value), refused.value


@pytest.mark.parametrize("count", ["0", "-1", " 3 "])
def test_a_count_below_one_makes_no_copy_as_in_mujoco(count):
    xml = replicate(count)
    m = mujoco.MjModel.from_xml_string(xml)
    assert lk.Model.from_mjcf(xml).names == [m.body(b).name for b in range(m.nbody)]


def in_a_body(inner: str) -> str:
    return '<mujoco><worldbody><body name="a"><geom size=".1"/><replicate count="2">' + inner + "</replicate></body></worldbody></mujoco>"


@pytest.mark.parametrize("child", ["<joint/>", "<freejoint/>"])
def test_a_joint_directly_in_a_replicate_is_refused_as_in_mujoco(child):
    with pytest.raises(ValueError, match="direct child of replicate"):
        mujoco.MjModel.from_xml_string(in_a_body(child))
    with pytest.raises(ValueError, match="cannot be a direct child of <replicate>"):
        lk.Model.from_mjcf(in_a_body(child))


def test_an_inertial_directly_in_a_replicate_is_ignored_as_in_mujoco():
    xml = in_a_body('<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/><geom size=".2"/>')
    m = mujoco.MjModel.from_xml_string(xml)
    assert lk.Model.from_mjcf(xml).body("a").mass == pytest.approx(m.body_mass[1], rel=1e-12)


@pytest.mark.parametrize(
    "xml",
    [
        replicate(str(10**12)),
        # Three levels of a thousand: 10⁹ copies of the body from a file of 300 bytes.
        replicate("1000", replicate("1000", replicate("1000")[len("<mujoco><worldbody>") : -len("</worldbody></mujoco>")])[
            len("<mujoco><worldbody>") : -len("</worldbody></mujoco>")
        ]),
    ],
    ids=["huge", "nested"],
)
def test_a_count_beyond_the_element_bound_is_a_memory_error_before_any_copy(xml):
    raises(f"lk.Model.from_mjcf({xml!r})", "MemoryError", "count=", "more than the 2000000 elements an MJCF may have", timeout=30)


@pytest.mark.slow
@pytest.mark.serial
def test_an_interrupted_expansion_stops_its_worker_thread(tmp_path):
    # 450,000 copies of a body (1.8 million elements, under the bound): interrupted halfway, the worker is cancelled.
    path = tmp_path / "model.mjcf"
    path.write_text(replicate("450000"))
    result = interrupted_load(path, "mjcf")
    assert result["worker_cpu_after"] < 0.25 * result["whole"], result
