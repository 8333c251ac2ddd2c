"""The MJCF schema, differentially against MuJoCo: a typo (an element or attribute MuJoCo does not know where it
stands) is refused by both, naming it, its element and its line; every name MuJoCo's own schema lists
(`mujoco.mj_printSchema`) passes legkit's check where MuJoCo lists it.
"""

from __future__ import annotations

import re
import warnings

import mujoco
import pytest

import legkit as lk


def body(inner: str) -> str:
    """`inner` at line 4, in a body."""
    return f'<mujoco>\n<worldbody>\n<body name="b">\n{inner}\n<geom size=".1"/></body></worldbody></mujoco>'


# The issue's typos and a few more, each with (name, element, line) in both tools' messages.
TYPOS = [
    (body('<joint dampng="1"/>'), "attribute", "dampng", "joint", 4),
    (body('<geom size=".1" desnity="10"/>'), "attribute", "desnity", "geom", 4),
    (body('<inertial mass="1" diaginertia="1 1 1" mas="5"/>'), "attribute", "mas", "inertial", 4),
    ('<mujoco>\n<compiler angel="radian"/>\n</mujoco>', "attribute", "angel", "compiler", 2),
    ("<mujoco>\n\n<foo/>\n</mujoco>", "element", "foo", "mujoco", 3),
    (body("<jiont/>"), "element", "jiont", "body", 4),
    (body('<freejoint dampng="1"/>'), "attribute", "dampng", "freejoint", 4),
    ('<mujoco>\n<default>\n<joint dampng="1"/>\n</default></mujoco>', "attribute", "dampng", "joint", 3),
    ('<mujoco>\n<default>\n<default class="a">\n<geom desnity="1"/></default></default></mujoco>', "attribute", "desnity", "geom", 4),
    ('<mujoco>\n<option>\n<flag gravty="disable"/></option></mujoco>', "attribute", "gravty", "flag", 3),
    ('<mujoco>\n<actuator>\n<motr joint="j"/></actuator></mujoco>', "element", "motr", "actuator", 3),
    ('<mujoco>\n<default><joint name="j"/></default></mujoco>', "attribute", "name", "joint", 2),
]


def mujoco_refusal(xml: str) -> str:
    with pytest.raises(ValueError) as refused:
        mujoco.MjModel.from_xml_string(xml)
    return str(refused.value)


@pytest.mark.parametrize(("xml", "kind", "name", "element", "line"), TYPOS, ids=[t[2] + "-in-" + t[3] for t in TYPOS])
def test_a_typo_is_refused_by_mujoco_and_legkit_naming_it_its_element_and_line(xml, kind, name, element, line):
    theirs = mujoco_refusal(xml)
    named = f"attribute: '{name}'\nElement '{element}'" if kind == "attribute" else f"element\nElement '{name}'"
    assert f"Schema violation: unrecognized {named}, line {line}" in theirs, theirs
    for strict in (False, True):
        with pytest.raises(ValueError) as refused:
            lk.load_mjcf(xml, strict=strict)
        ours = str(refused.value)
        where = f'attribute "{name}" in <{element}>' if kind == "attribute" else f"element <{name}> in <{element}>"
        assert ours.startswith(f"mjcf: schema violation at line {line} of <string>: unrecognized {where}"), ours


def test_a_typo_in_an_included_file_names_that_file_and_its_line(tmp_path):
    """MuJoCo refuses it too, at "line 0" (its includes keep no lines)."""
    (tmp_path / "part.xml").write_text('<mujoco>\n<worldbody>\n<body><geom size=".1" desnity="1"/></body></worldbody></mujoco>')
    (tmp_path / "main.xml").write_text('<mujoco>\n<include file="part.xml"/>\n</mujoco>')
    with pytest.raises(ValueError, match="Schema violation: unrecognized attribute: 'desnity'"):
        mujoco.MjModel.from_xml_path(str(tmp_path / "main.xml"))
    with pytest.raises(ValueError, match=r'^mjcf: schema violation at line 3 of part.xml: unrecognized attribute "desnity" in <geom>'):
        lk.load_mjcf(str(tmp_path / "main.xml"))


def mujoco_schema() -> list[list[str]]:
    """Every element of MuJoCo's schema as its path from <mujoco> followed by its attributes (`mj_printSchema`)."""
    rows: list[tuple[list[str], list[str]]] = []
    path: list[str] = []
    for line in mujoco.mj_printSchema(False, False).splitlines():
        named = re.match(r"^( *)(\S+) \((.)\)(.*)$", line)
        if named:
            path = [*path[: len(named.group(1)) // 3], named.group(2)]
            rows.append((path, named.group(4).split()))
        elif line.strip():
            rows[-1][1].extend(line.split())
    return rows


SCHEMA = mujoco_schema()


def document(path: list[str], attribute: str | None = None, child: str | None = None) -> tuple[str, str]:
    """The elements of `path` nested, the last at line 2 with `attribute` (="0") or holding `child` at line 3,
    and that element's tag. MuJoCo's "(world)body" row is a body's: a body in the world body."""
    tags = [t for tag in path for t in (["worldbody", "body"] if tag == "(world)body" else [tag])]
    last = f'<{tags[-1]} {attribute}="0"/>' if attribute else f"<{tags[-1]}>\n<{child}/></{tags[-1]}>" if child else f"<{tags[-1]}/>"
    xml = "".join(f"<{t}>" for t in tags[:-1]) + "\n" + last + "".join(f"</{t}>" for t in reversed(tags[:-1]))
    return xml, tags[-1]


def test_every_name_in_mujocos_schema_passes_legkits_check_where_mujoco_lists_it():
    """Each element MuJoCo lists, alone and with each of its attributes, in a document of its own: legkit may
    refuse the value "0" or what the document lacks, but never as a schema violation."""
    checked = 0
    for path, attributes in SCHEMA:
        for attribute in [None, *attributes]:
            xml, _ = document(path, attribute)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    lk.load_mjcf(xml)
                except (ValueError, RuntimeError, MemoryError) as error:
                    assert "schema violation" not in str(error), (xml, str(error))
            checked += 1
    assert len(SCHEMA) > 150 and checked > 1800, (len(SCHEMA), checked)


@pytest.mark.parametrize("path", [path for path, _ in SCHEMA], ids=["/".join(path) for path, _ in SCHEMA])
def test_an_unknown_attribute_or_child_of_any_element_mujoco_lists_is_refused_by_both_at_its_line(path):
    xml, tag = document(path, attribute="zzqq")
    assert f"Schema violation: unrecognized attribute: 'zzqq'\nElement '{tag}', line 2" in mujoco_refusal(xml)
    with pytest.raises(ValueError, match=rf'^mjcf: schema violation at line 2 of <string>: unrecognized attribute "zzqq" in <{tag}>'):
        lk.load_mjcf(xml)
    xml, tag = document(path, child="zzqq")
    theirs = mujoco_refusal(xml)
    # MuJoCo checks an element's required attributes (connect's body1 or site1, ...) before its children.
    assert "Schema violation: unrecognized element\nElement 'zzqq', line 3" in theirs or (
        re.search(rf"Schema violation: one of .* must be specified\nElement '{tag}', line 2", theirs)
    ), theirs
    with pytest.raises(ValueError, match=rf"^mjcf: schema violation at line 3 of <string>: unrecognized element <zzqq> in <{tag}>"):
        lk.load_mjcf(xml)


def test_a_second_element_mujoco_allows_once_is_refused_by_both():
    xml = body('<inertial mass="1" diaginertia="1 1 1"/>\n<inertial mass="2" diaginertia="1 1 1"/>')
    assert "unique element 'inertial' found 2 times" in mujoco_refusal(xml)
    with pytest.raises(ValueError, match=r"^mjcf: schema violation at line 5 of <string>: a second <inertial> in <body>"):
        lk.load_mjcf(xml)


@pytest.mark.parametrize(
    ("inner", "refused"),
    [
        ('<frame pos="1 0 0" mocap="true"><geom size=".1"/></frame>', 'attribute "mocap" in <frame>'),
        ('<frame><geom size=".1" desnity="1"/></frame>', 'attribute "desnity" in <geom>'),
        ('<replicate count="2" offst="1 0 0"><geom size=".1"/></replicate>', 'attribute "offst" in <replicate>'),
        ('<replicate count="2"><body><joint dampng="1"/><geom size=".1"/></body></replicate>', 'attribute "dampng" in <joint>'),
    ],
)
def test_typos_inside_frames_and_replicates_are_refused_where_mujocos_validator_skips_them(inner, refused):
    """MuJoCo 4.0 checks frames and replicates against no row (mjXSchema::NameMatch lets them pass unchecked) and
    loads these files without the typo's effect; legkit checks them with their own attributes."""
    xml = f"<mujoco><worldbody>\n{inner}</worldbody></mujoco>"
    mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(ValueError, match=rf"^mjcf: schema violation at line 2 of <string>: unrecognized {refused}"):
        lk.load_mjcf(xml)
