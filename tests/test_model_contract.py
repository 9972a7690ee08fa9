"""The contract of the model layer (issue 11): bad inputs raise a VjmError subclass with a
one-line message naming the problem; unknown `vjm:` tags are refused; a spring
specification is validated as a whole; spring `dofs` are honoured in any order (issue 12)."""

from __future__ import annotations

import importlib.util
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from vjm_pin import load_vjm, loaded_stiffness, solve_equilibrium, unloaded_stiffness
from vjm_pin.model.beam import Beam, section_properties
from vjm_pin.cli import main
from vjm_pin.exceptions import (
    ArgumentError,
    FrameNotFound,
    InputError,
    JointNotFound,
    ModelError,
    SpecError,
    SpecProblems,
    UnknownVjmTag,
    UrdfParseError,
    VjmError,
)
from vjm_pin.model.generator import generate_vjm
from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.model.format import NS, VJM_TAGS, check_vjm_tags, vjm_tags_markdown
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf, paper_spec, rigid_chain_urdf
from vjm_pin.model.registry import bundled_models, resolve_model
from vjm_pin.model.robots import build_robot, parse_q
from vjm_pin.model.spec import read_spec
from vjm_pin.model.subdivide import subdivide_vjm

ROOT = Path(__file__).resolve().parent.parent
A = paper_model_urdf("a", "s")
B = paper_model_urdf("b", "s", beam=PAPER_BEAM)
VM = load_vjm(A)
RIGID = rigid_chain_urdf(planar=True)
TUBE = {"section": "tube", "outer_diameter": 0.09, "wall": 0.005, "E": 7.0e10, "nu": 0.33}


@pytest.fixture
def files(tmp_path):
    """Bad files of every kind, by name."""
    (tmp_path / "binary.urdf").write_bytes(bytes(range(256)) * 4)
    (tmp_path / "svg.urdf").write_text("<svg><g/></svg>")
    (tmp_path / "folder").mkdir()
    (tmp_path / "empty.yaml").write_text("")
    (tmp_path / "syntax.yaml").write_text("actuators:\n  a: 1\n b: [\n")
    (tmp_path / "latin1.yaml").write_bytes(b"actuators:\n  elbow_joint: \xff\xfe\n")
    (tmp_path / "twice.yaml").write_text("actuators:\n  elbow_joint: 1.0e5\n  elbow_joint: 2.0e5\n")
    (tmp_path / "list.yaml").write_text("- actuators\n- links\n")
    (tmp_path / "origin.urdf").write_text(RIGID.replace('<origin xyz="1.0 0 0"/>', '<origin xyz="1.0 zero 0"/>', 1))
    (tmp_path / "limit.urdf").write_text(RIGID.replace('lower="-1000.0"', 'lower="low"', 1))
    return tmp_path


# --------------------------------------------------------------------------- Python API table
#: (id, call(files) -> anything, expected class, fragment of the message)
API_CASES = [
    ("load_vjm missing", lambda f: load_vjm(f / "nope.urdf"), UrdfParseError, "not found"),
    ("load_vjm folder", lambda f: load_vjm(f / "folder"), UrdfParseError, "is a folder"),
    ("load_vjm binary", lambda f: load_vjm(f / "binary.urdf"), UrdfParseError, "not UTF-8"),
    ("load_vjm not URDF", lambda f: load_vjm(f / "svg.urdf"), UrdfParseError, "<svg>"),
    ("load_vjm int", lambda f: load_vjm(123), ArgumentError, "got int"),
    ("load_vjm None", lambda f: load_vjm(None), ArgumentError, "got NoneType"),
    ("load_vjm bytes", lambda f: load_vjm(b"<robot/>"), ArgumentError, "got bytes"),
    ("load_vjm empty", lambda f: load_vjm(""), ArgumentError, "empty"),
    ("load_vjm beam E", lambda f: load_vjm(B.replace(' E="', ' E="abc', 1)), ModelError, "beam 'E'"),
    ("load_vjm position ''", lambda f: load_vjm(A.replace('position="-0.0"', 'position=""', 1)), ModelError, "one number"),
    ("load_vjm position 2 numbers", lambda f: load_vjm(A.replace('position="-0.0"', 'position="1 2"', 1)), ModelError, "one number"),
    ("load_vjm spring twice", lambda f: load_vjm(B.replace('name="link2" link="link2"', 'name="link1" link="link2"')), ModelError, "two <vjm:spring> elements named 'link1'"),
    ("with_positions unknown", lambda f: VM.with_positions({"ghost": 1}), JointNotFound, "ghost"),
    ("with_positions str", lambda f: VM.with_positions({"qa1": "abc"}), ArgumentError, "'qa1'"),
    ("with_positions None", lambda f: VM.with_positions({"qa1": None}), ArgumentError, "must be a number"),
    ("with_positions bool", lambda f: VM.with_positions({"qa1": True}), ArgumentError, "must be a number"),
    ("with_positions list", lambda f: VM.with_positions(["qa1"]), ArgumentError, "must be a dict"),
    ("with_positions nan", lambda f: VM.with_positions({"qa1": float("nan")}), InputError, "finite"),
    ("Kinematics frame id", lambda f: Kinematics(VM.model, 999), ArgumentError, "frame_id"),
    ("Kinematics model None", lambda f: Kinematics(None, 0), ArgumentError, "pinocchio.Model"),
    ("Kinematics.evaluate size", lambda f: Kinematics(VM.model, VM.frame_id).evaluate(np.zeros(VM.model.nq + 2)), InputError, f"x must be {VM.model.nq} numbers"),
    ("Kinematics.evaluate str", lambda f: Kinematics(VM.model, VM.frame_id).evaluate("abc"), InputError, "x must be"),
    ("Kinematics.placement size", lambda f: Kinematics(VM.model, VM.frame_id).placement(np.zeros(1)), InputError, "x must be"),
    ("psi_hessian without", lambda f: Kinematics(VM.model, VM.frame_id).evaluate(VM.reference, hessian=False).psi_hessian(np.zeros(6)), InputError, "without Hessian"),
    ("psi_hessian size", lambda f: Kinematics(VM.model, VM.frame_id).evaluate(VM.reference).psi_hessian(np.zeros(3)), InputError, "wrench must be 6"),
    ("resolve_model unknown", lambda f: resolve_model("nosuch-model"), ModelError, "nosuch-model"),
    ("resolve_model int", lambda f: resolve_model(123), ArgumentError, "name_or_path"),
    ("resolve_model None", lambda f: resolve_model(None), ArgumentError, "name_or_path"),
    ("resolve_model q str", lambda f: resolve_model("paper-a-s", q="qa1=1"), ArgumentError, "q must be a dict"),
    ("resolve_model q unknown", lambda f: resolve_model("paper-a-s", q={"bogus": 1}), JointNotFound, "bogus"),
    ("resolve_model binary", lambda f: resolve_model(str(f / "binary.urdf")), ModelError, "not UTF-8"),
    ("resolve_model folder", lambda f: resolve_model(str(f / "folder")), ModelError, "is a folder"),
    ("build_robot frame unknown", lambda f: build_robot("ur5", frame="nope"), FrameNotFound, "nope"),
    ("build_robot frame int", lambda f: build_robot("ur5", frame=5), ArgumentError, "frame must be"),
    ("build_robot q str", lambda f: build_robot("ur5", q="abc"), ArgumentError, "q must be a dict"),
    ("build_robot q value", lambda f: build_robot("ur5", q={"elbow_joint": "abc"}), ArgumentError, "elbow_joint"),
    ("build_robot pose_name", lambda f: build_robot("panda", pose_name="nope"), InputError, "no named pose 'nope'"),
    ("build_robot pose_name int", lambda f: build_robot("panda", pose_name=3), ArgumentError, "pose_name"),
    ("build_robot bad origin", lambda f: build_robot(f / "origin.urdf"), UrdfParseError, "origin xyz: expected a number, got 'zero'"),
    ("build_robot bad limit", lambda f: build_robot(f / "limit.urdf"), UrdfParseError, "limit lower: expected a number, got 'low'"),
    ("build_robot source int", lambda f: build_robot(123), ArgumentError, "source must be"),
    ("build_robot springs int", lambda f: build_robot("ur5", springs=42), ArgumentError, "spring specification must be"),
    ("build_robot springs list", lambda f: build_robot("ur5", springs=["a"]), ArgumentError, "spring specification must be"),
    ("springs actuators str", lambda f: build_robot("ur5", springs={"actuators": "x"}), SpecProblems, "actuators: expected a mapping, got 'x'"),
    ("springs links list", lambda f: build_robot("ur5", springs={"links": ["l1"]}), SpecProblems, "links: expected a mapping"),
    ("springs positions str", lambda f: build_robot("ur5", springs={"positions": {"elbow_joint": "abc"}}), SpecProblems, "positions.elbow_joint: expected a number, got 'abc'"),
    ("springs passive str", lambda f: build_robot("ur5", springs={"passive": "elbow_joint"}), SpecProblems, "passive: expected a list"),
    ("springs stiffness -1", lambda f: build_robot("ur5", springs={"actuators": {"default": -1}}), SpecProblems, "actuators.default: must be positive"),
    ("springs stiffness 0", lambda f: build_robot("ur5", springs={"actuators": {"elbow_joint": 0}}), SpecProblems, "actuators.elbow_joint: must be positive"),
    ("springs unknown key", lambda f: build_robot("ur5", springs={"actuatos": {}}), SpecProblems, "did you mean 'actuators'"),
    ("springs beam E", lambda f: build_robot("ur5", springs={"links": {"forearm_link": {"beam": dict(TUBE, E="abc")}}}), SpecProblems, "links.forearm_link.beam.E: expected a number, got 'abc'"),
    ("springs beam key", lambda f: build_robot("ur5", springs={"links": {"forearm_link": {"beam": dict(TUBE, lenght=1)}}}), SpecProblems, "did you mean 'length'"),
    ("springs missing file", lambda f: build_robot("ur5", springs=str(f / "nope.yaml")), SpecProblems, "file not found"),
    ("springs folder", lambda f: build_robot("ur5", springs=str(f / "folder")), SpecProblems, "is a folder"),
    ("springs not UTF-8", lambda f: build_robot("ur5", springs=str(f / "latin1.yaml")), SpecProblems, "latin1.yaml: not a YAML text file"),
    ("springs empty", lambda f: build_robot("ur5", springs=str(f / "empty.yaml")), SpecProblems, "empty.yaml: empty document"),
    ("springs syntax", lambda f: build_robot("ur5", springs=str(f / "syntax.yaml")), SpecProblems, "syntax.yaml: line 3, column 2: not valid YAML"),
    ("springs key twice", lambda f: build_robot("ur5", springs=str(f / "twice.yaml")), SpecProblems, "'elbow_joint' is given twice"),
    ("springs a list", lambda f: build_robot("ur5", springs=str(f / "list.yaml")), SpecProblems, "expected a mapping"),
    ("parse_q no =", lambda f: parse_q(["a"]), InputError, "NAME=VALUE"),
    ("parse_q str", lambda f: parse_q("elbow_joint=1"), ArgumentError, "list of 'NAME=VALUE'"),
    ("parse_q int item", lambda f: parse_q([1]), InputError, "NAME=VALUE"),
    ("parse_q no name", lambda f: parse_q(["=1"]), InputError, "no joint name"),
    ("parse_q value", lambda f: parse_q(["a=b"]), InputError, "not a number"),
    ("generate_vjm spec int", lambda f: generate_vjm(RIGID, 5), ArgumentError, "spring specification must be"),
    ("generate_vjm no frame", lambda f: generate_vjm(RIGID, {"task": ["x"]}), SpecProblems, "frame: required"),
    ("generate_vjm task int", lambda f: generate_vjm(RIGID, {"frame": "end", "task": 5}), SpecProblems, "task: expected a list"),
    ("generate_vjm subdivide bool", lambda f: generate_vjm(RIGID, {"frame": "end", "subdivide": True}), SpecProblems, "subdivide: expected a positive integer"),
    ("generate_vjm position bool", lambda f: generate_vjm(RIGID, {"frame": "end", "positions": {"qa1": True}}), SpecProblems, "positions.qa1: expected a number, got True"),
    ("generate_vjm rest str", lambda f: generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"stiffness": [[1.0]], "dofs": "x", "rest": "abc"}}}), SpecProblems, "links.link1.rest: expected a list"),
    ("generate_vjm rest length", lambda f: generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"stiffness": [[1.0]], "dofs": "x", "rest": [0, 0]}}}), SpecProblems, "'rest' has 2 values for 1 dofs"),
    ("generate_vjm both beam and K", lambda f: generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"stiffness": [[1.0]], "beam": TUBE}}}), SpecProblems, "exactly one of 'beam' or 'stiffness'"),
    ("generate_vjm stiffness inf", lambda f: generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"stiffness": [[float("inf")]], "dofs": "x"}}}), SpecProblems, "finite"),
    ("generate_vjm dofs repeated", lambda f: generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"beam": TUBE, "dofs": "x x"}}}), SpecProblems, "distinct"),
    ("generate_vjm section dims", lambda f: generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"beam": dict(TUBE, a=0.1)}}}), SpecProblems, "does not take a"),
    ("generate_vjm missing rigid", lambda f: generate_vjm(f / "nope.urdf", {"frame": "end"}), UrdfParseError, "not found"),
    ("Beam E str", lambda f: Beam.from_dict(dict(TUBE, length=1, E="abc")), SpecError, "'E' must be a number"),
    ("Beam not a dict", lambda f: Beam.from_dict("x"), SpecError, "mapping"),
    ("Beam nu -1", lambda f: Beam.from_dict(dict(TUBE, length=1, nu=-1)), SpecError, "(-1, 0.5]"),
    ("Beam nu 0.7", lambda f: Beam.from_dict(dict(TUBE, length=1, nu=0.7)), SpecError, "(-1, 0.5]"),
    ("Beam.split 0", lambda f: Beam.from_dict(dict(TUBE, length=1)).split(0), SpecError, "positive integer"),
    ("section_properties str", lambda f: section_properties("circle", diameter="abc"), SpecError, "'diameter' must be a number"),
    ("subdivide k=0", lambda f: subdivide_vjm(B, 0), SpecError, "positive integer"),
    ("subdivide k str", lambda f: subdivide_vjm(B, "2"), SpecError, "positive integer"),
    ("subdivide no beam", lambda f: subdivide_vjm(A, 2), ModelError, "nothing to subdivide"),
    ("subdivide beam E", lambda f: subdivide_vjm(B.replace(' E="', ' E="abc', 1), 2), ModelError, "beam 'E'"),
    ("paper_spec model", lambda f: paper_spec("d", "s"), ArgumentError, "'a', 'b' or 'c'"),
    ("paper_spec posture", lambda f: paper_spec("a", "q"), ArgumentError, "posture 'q'"),
    ("paper_spec no beam", lambda f: paper_spec("b", "s"), ArgumentError, "beam parameters"),
    ("paper_model_urdf int", lambda f: paper_model_urdf(1, "s"), ArgumentError, "paper model 1"),
]


@pytest.mark.parametrize("call,exc,fragment", [c[1:] for c in API_CASES], ids=[c[0] for c in API_CASES])
def test_api_misuse_raises_a_vjm_error_naming_the_problem(files, call, exc, fragment):
    with pytest.raises(exc) as info:
        call(files)
    assert isinstance(info.value, VjmError)
    msg = str(info.value)
    assert fragment in msg, msg
    assert "\n" not in msg, f"not one line: {msg!r}"


# --------------------------------------------------------------------------- vjm tags
#: (id, edit of a paper model, name in the message, suggestion in the message)
TAG_CASES = [
    ("element typo", lambda t: t.replace('<vjm:joint name="qa1"', '<vjm:jiont name="qa1"'), "<vjm:jiont>", "did you mean 'vjm:joint'"),
    ("child typo", lambda t: t.replace("vjm:rest", "vjm:rset"), "<vjm:rset>", "did you mean 'vjm:rest'"),
    ("attribute typo", lambda t: t.replace('role="actuated"', 'rol="actuated"', 1), "'rol'", "did you mean 'role'"),
    ("beam attribute typo", lambda t: t.replace(' section="', ' sectoin="', 1), "'sectoin'", "did you mean 'section'"),
    ("no prefix inside spring", lambda t: t.replace("vjm:rest", "rest"), "<rest>", "did you mean 'vjm:rest'"),
    ("vjm attribute on URDF joint", lambda t: t.replace('<joint name="qa1"', '<joint vjm:role="passive" name="qa1"', 1), "'vjm:role'", "defines no attributes"),
    ("misplaced", lambda t: t.replace('<link name="link2" />', '<link name="link2"><vjm:rest>0</vjm:rest></link>', 1), "<vjm:rest>", "belongs inside <vjm:spring>"),
    ("newer version", lambda t: t.replace("</robot>", '<x:task xmlns:x="urn:vjm-pin:2" frame="end"/></robot>'), "urn:vjm-pin:2", "reads 'urn:vjm-pin:1'"),
]


@pytest.mark.parametrize("edit,name,hint", [c[1:] for c in TAG_CASES], ids=[c[0] for c in TAG_CASES])
def test_unknown_vjm_tags_are_refused_with_place_and_known_names(edit, name, hint):
    bad = edit(B)
    assert bad != B, "the edit must change the model"
    with pytest.raises(UnknownVjmTag) as info:
        load_vjm(bad)
    msg = str(info.value)
    assert name in msg and hint in msg, msg
    # the reported line holds the offending element
    line = info.value.line
    assert line is not None and name.strip("<>'").split(":")[-1] in bad.splitlines()[line - 1]


def test_an_unknown_tag_would_otherwise_change_the_mechanism():
    """The reason for refusing: a misspelt stiffness attribute silently locks the joint."""
    typo = A.replace('stiffness="1.0"', 'stifness="1.0"', 1)
    assert typo != A
    root = ET.fromstring(typo)
    tagged = [el.get("name") for el in root.findall(f"{{{NS}}}joint") if el.get("stiffness")]
    assert len(tagged) == len(VM.theta_idx) - 1  # what a loader ignoring the typo would see
    with pytest.raises(UnknownVjmTag, match="stifness"):
        load_vjm(typo)


def test_docs_table_is_the_loader_table():
    text = (ROOT / "docs" / "format.md").read_text()
    block = re.search(r"<!-- vjm-tags:begin[^\n]*-->\n(.*?)<!-- vjm-tags:end -->", text, re.DOTALL)
    assert block, "docs/format.md lost its vjm-tags markers"
    assert block.group(1) == vjm_tags_markdown(), "regenerate the table: vjm_pin.model.format.vjm_tags_markdown()"


def _vjm_elements(text: str):
    for el in ET.fromstring(text).iter():
        if el.tag.startswith(f"{{{NS}}}"):
            yield el.tag.split("}")[1], set(el.attrib)


def _load_orthoglide_script():
    path = ROOT / "scripts" / "make_orthoglide.py"
    spec = importlib.util.spec_from_file_location("make_orthoglide_contract", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_generators_write_only_known_tags():
    texts = [paper_model_urdf(m, p, beam=PAPER_BEAM) for m in "abc" for p in ("s", "pi", "z")]
    texts.append(subdivide_vjm(B, 3))
    texts.append(generate_vjm(RIGID, {"frame": "end", "links": {"link1": {"beam": TUBE, "dofs": ["rz", "x", "y"]}}}))
    texts += list(_load_orthoglide_script().orthoglide_models().values())
    closed = importlib.util.spec_from_file_location("make_closed_models_contract", ROOT / "scripts" / "make_closed_models.py")
    closed_mod = importlib.util.module_from_spec(closed)
    closed.loader.exec_module(closed_mod)
    texts += list(closed_mod.closed_models().values())
    seen = set()
    for text in texts:
        for tag, attrs in _vjm_elements(text):
            assert tag in VJM_TAGS, tag
            assert attrs <= set(VJM_TAGS[tag].attributes), (tag, attrs - set(VJM_TAGS[tag].attributes))
            seen.add(tag)
        check_vjm_tags(text)
    assert seen == set(VJM_TAGS), f"tags no generator writes: {set(VJM_TAGS) - seen}"


def test_every_bundled_model_loads():
    models = bundled_models()
    assert len(models) >= 24
    for name, path in models.items():
        vm = load_vjm(path)
        assert vm.n_theta > 0, name
        legs = sum(1 for tag, _ in _vjm_elements(path.read_text()) if tag == "leg")
        assert len(vm.legs) == legs and (legs == 0 or legs >= 3), name
        if legs:  # the shorthand: one closure per leg but the first
            assert len(vm.closures) >= legs - 1, name


# --------------------------------------------------------------------------- spec as a whole
def test_every_spec_problem_is_reported_at_once_with_path_and_file(tmp_path):
    p = tmp_path / "arm.yaml"
    p.write_text(
        "actuators: x\n"
        "links:\n"
        "  forearm_link:\n"
        "    beam: {section: tube, outer_diameter: 0.09, wall: 0.005, E: abc, nu: 0.3}\n"
        "positions: {elbow_joint: abc}\n"
        "passive: elbow_joint\n"
        "subdivde: 2\n"
    )
    with pytest.raises(SpecProblems) as info:
        read_spec(p, require_frame=False)
    err = info.value
    assert err.source == str(p) and "<unicode string>" not in str(err)
    assert [q.split(":")[0] for q in err.problems] == [
        "actuators", "links.forearm_link.beam.E", "positions.elbow_joint", "passive", "subdivde"
    ]
    assert "did you mean 'subdivide'" in err.problems[-1]
    assert str(err).startswith(f"spring specification {p}: 5 problems: ") and "\n" not in str(err)


def test_valid_spec_is_normalised_without_adding_keys():
    spec = read_spec("frame: tool0\nactuators: {default: 1e5, elbow_joint: null}\nlinks:\n  l: {stiffness: [[2]], dofs: rz}\n")
    assert spec == {
        "frame": "tool0",
        "actuators": {"default": 1.0e5, "elbow_joint": None},
        "links": {"l": {"stiffness": [[2.0]], "dofs": ["rz"]}},
    }


# --------------------------------------------------------------------------- dofs order (issue 12.6)
def _planar_model(order, k_canonical, rest_canonical):
    """Model B's rigid chain with one 3-D link spring given in ``order``."""
    canon = ["x", "y", "rz"]
    perm = [canon.index(d) for d in order]
    k = np.asarray(k_canonical)[np.ix_(perm, perm)]
    spec = {
        "frame": "end",
        "task": ["x", "y"],
        "passive": ["base_z"],
        "actuators": {"qa1": 50.0, "qa2": 80.0},
        "links": {"link2": {"stiffness": k.tolist(), "dofs": list(order), "rest": [rest_canonical[i] for i in perm]}},
    }
    return load_vjm(generate_vjm(RIGID, spec))


def _by_name(vm):
    names = vm.theta_names
    order = sorted(range(len(names)), key=lambda i: names[i])
    return [names[i] for i in order], vm.K_theta[np.ix_(order, order)], vm.theta0[order]


@pytest.mark.parametrize("order", [["rz", "x", "y"], ["y", "rz", "x"], ["x", "rz", "y"]])
def test_link_spring_dofs_in_any_order_give_the_same_spring(order):
    k = np.array([[3.0e5, 0.0, 0.0], [0.0, 2.0e4, 1.5e3], [0.0, 1.5e3, 4.0e2]])  # y-rz coupled
    rest = [1e-4, -2e-4, 3e-3]
    ref = _planar_model(["x", "y", "rz"], k, rest)
    other = _planar_model(order, k, rest)
    n1, k1, r1 = _by_name(ref)
    n2, k2, r2 = _by_name(other)
    assert n1 == n2
    np.testing.assert_allclose(k2, k1, rtol=1e-14)
    np.testing.assert_allclose(r2, r1, rtol=1e-14)
    # the spring's own joints, by name: x is the axial joint, rz the bending rotation
    assert k1[n1.index("link2_vjm_tx"), n1.index("link2_vjm_tx")] == pytest.approx(3.0e5)
    assert k1[n1.index("link2_vjm_rz"), n1.index("link2_vjm_ty")] == pytest.approx(1.5e3)
    np.testing.assert_allclose(unloaded_stiffness(other).stiffness, unloaded_stiffness(ref).stiffness, rtol=1e-10)
    d = np.array([2e-3, -1e-3, 0.0, 0.0, 0.0, 0.0])  # m: a loaded equilibrium
    eqs = [solve_equilibrium(vm, d) for vm in (ref, other)]
    assert all(eq.converged for eq in eqs)
    np.testing.assert_allclose(eqs[1].wrench, eqs[0].wrench, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(
        loaded_stiffness(other, eqs[1]).stiffness, loaded_stiffness(ref, eqs[0]).stiffness, rtol=1e-8, atol=1e-9
    )


def test_spatial_spring_random_permutation_matches_the_canonical_one():
    rng = np.random.default_rng(7)
    m = rng.normal(size=(6, 6))
    k = m @ m.T + 6.0 * np.eye(6)
    comps = ["x", "y", "z", "rx", "ry", "rz"]
    perm = list(rng.permutation(6))
    rigid = rigid_chain_urdf(planar=False)

    def model(order, kk):
        spec = {"frame": "end", "task": ["x", "y", "z"], "passive": ["base_z", "base_y"],
                "actuators": {"qa1": 1.0, "qa2": 1.0}, "links": {"link1": {"stiffness": kk.tolist(), "dofs": order}}}
        return load_vjm(generate_vjm(rigid, spec))

    a = _by_name(model(comps, k))
    b = _by_name(model([comps[i] for i in perm], k[np.ix_(perm, perm)]))
    np.testing.assert_allclose(b[1], a[1], rtol=1e-13)


# --------------------------------------------------------------------------- CLI table
def _vjm_file(tmp_path, edit):
    p = tmp_path / "model.urdf"
    p.write_text(edit(B))
    return str(p)


def _yaml_file(tmp_path, text):
    p = tmp_path / "springs.yaml"
    p.write_text(text)
    return str(p)


def _bytes_file(tmp_path, data):
    p = tmp_path / "latin1.yaml"
    p.write_bytes(data)
    return str(p)


#: (id, argv(tmp_path), fragment of the one-line error)
CLI_CASES = [
    ("tag typo", lambda t: ["analyze", _vjm_file(t, TAG_CASES[0][1])], "unknown element <vjm:jiont>"),
    ("attribute typo", lambda t: ["analyze", _vjm_file(t, TAG_CASES[2][1])], "unknown attribute 'rol'"),
    ("no prefix", lambda t: ["analyze", _vjm_file(t, TAG_CASES[4][1])], "<rest> inside <vjm:spring> has no vjm: prefix"),
    ("spec actuators str", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, 'actuators: "x"\n')], "springs.yaml: actuators: expected a mapping"),
    ("spec links list", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "links: [l1]\n")], "links: expected a mapping"),
    ("spec positions", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "positions: {elbow_joint: abc}\n")], "positions.elbow_joint: expected a number, got 'abc'"),
    ("spec passive str", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "passive: elbow_joint\n")], "passive: expected a list"),
    ("spec negative k", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "actuators: {elbow_joint: -5}\n")], "must be positive"),
    ("spec unknown key", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "actuator: {}\n")], "did you mean 'actuators'"),
    ("spec beam E", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "links:\n  forearm_link:\n    beam: {section: tube, outer_diameter: 0.09, wall: 0.005, E: abc, nu: 0.3}\n")], "links.forearm_link.beam.E: expected a number, got 'abc'"),
    ("spec several", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "actuators: x\npassive: j\n")], "2 problems"),
    ("spec syntax", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "a: [\n")], "not valid YAML"),
    ("spec empty", lambda t: ["analyze", "ur5", "--springs", _yaml_file(t, "")], "empty document"),
    ("spec not UTF-8", lambda t: ["analyze", "ur5", "--springs", _bytes_file(t, b"a: \xff\xfe\n")], "not UTF-8"),
    ("spec folder", lambda t: ["analyze", "ur5", "--springs", str(t)], "is a folder"),
    ("spec missing", lambda t: ["analyze", "ur5", "--springs", str(t / "nope.yaml")], "file not found"),
]


@pytest.mark.parametrize("argv,fragment", [c[1:] for c in CLI_CASES], ids=[c[0] for c in CLI_CASES])
def test_cli_bad_model_or_spec_is_one_error_line(tmp_path, capsys, argv, fragment):
    rc = main(argv(tmp_path))
    err = capsys.readouterr().err
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("vjm-pin: error:"), err
    assert fragment in lines[0], err
    assert "Traceback" not in err
