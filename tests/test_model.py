"""The VJM URDF format: generation, loading, validation and its errors."""

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin import (
    FrameNotFound,
    InputError,
    JointNotFound,
    RoleError,
    SpecError,
    StiffnessMatrixError,
    UrdfParseError,
    generate_vjm,
    load_vjm,
)
from vjm_pin.cli import main
from vjm_pin.model.paper_models import PAPER_BEAM, paper_model_urdf, rigid_chain_urdf


def test_stock_pinocchio_loads_a_vjm_urdf():
    text = paper_model_urdf("c", "s", beam=PAPER_BEAM)
    model = pin.buildModelFromXML(text)
    vm = load_vjm(text)
    assert model.nq == vm.model.nq == 2 + 18 + 2  # U joint, 3 × 6-D springs, 2 locked actuators
    assert vm.n_q == 2 and vm.n_theta == 18 and vm.task == (0, 1, 2)
    assert vm.roles["qa1"] == "locked" and vm.roles["base_y"] == "passive"
    assert all(g.beam is not None and g.beam["E"] == pytest.approx(PAPER_BEAM["E"]) for g in vm.springs)


def test_generated_spring_reproduces_beam_stiffness_and_tip_location():
    text = paper_model_urdf("c", "z", beam=PAPER_BEAM)
    vm = load_vjm(text)
    rigid = pin.buildModelFromXML(rigid_chain_urdf(planar=False))
    q = np.array([vm.reference[vm.joint_index(n)] for n in rigid.names[1:]])
    d = rigid.createData()
    pin.framesForwardKinematics(rigid, d, q)
    dv = vm.model.createData()
    pin.framesForwardKinematics(vm.model, dv, vm.reference)
    assert np.allclose(d.oMf[rigid.getFrameId("end")].translation, dv.oMf[vm.frame_id].translation, atol=1e-12)
    assert abs(dv.oMf[vm.frame_id].translation[1]) < 1e-12  # base angle puts the end on the x axis
    from vjm_pin.model.beam import Beam

    k = Beam.from_dict({**PAPER_BEAM, "length": 1.0}).stiffness()
    assert np.allclose(vm.springs[0].stiffness, k, rtol=1e-10)


def test_spec_dict_and_yaml_are_equivalent(tmp_path):
    import yaml

    spec = {"frame": "end", "task": ["x", "y"], "passive": ["base_z"], "actuators": {"default": 2.0}, "positions": {"qa1": 0.3}}
    p = tmp_path / "spec.yaml"
    p.write_text(yaml.safe_dump(spec))
    rigid = rigid_chain_urdf(planar=True)
    assert generate_vjm(rigid, spec) == generate_vjm(rigid, str(p))
    vm = load_vjm(generate_vjm(rigid, spec))
    assert np.allclose(vm.K_theta, 2.0 * np.eye(2)) and vm.theta0[0] == pytest.approx(0.3)


@pytest.mark.parametrize(
    "spec,exc,match",
    [
        ({"frame": "nowhere"}, FrameNotFound, "nowhere"),
        ({"frame": "end", "passive": ["ghost"]}, JointNotFound, "ghost"),
        ({"frame": "end", "colour": "red"}, SpecError, "colour"),
        ({"frame": "end", "links": {"link1": {"stiffness": [[1, 0], [0, 1]]}}}, StiffnessMatrixError, "shape"),
        ({"frame": "end", "links": {"link1": {"stiffness": np.diag([1, 1, 1, 1, 1, -1.0]).tolist()}}}, StiffnessMatrixError, "positive definite"),
        ({"frame": "end", "links": {"link1": {"beam": {"section": "circle", "diameter": 0.01, "E": 1e9, "nu": 0.3}, "dofs": ["x", "q"]}}}, SpecError, "'q'"),
        ({"frame": "end", "actuators": {"qa1": "stiff"}}, SpecError, "number"),
        ({"frame": "end", "task": "x y w"}, SpecError, "'w'"),
    ],
)
def test_bad_specs_raise_clear_errors(spec, exc, match):
    with pytest.raises(exc, match=match):
        generate_vjm(rigid_chain_urdf(), spec)


def _good():
    return paper_model_urdf("a", "s")


@pytest.mark.parametrize(
    "edit,exc,match",
    [
        (lambda t: t.replace("</robot>", ""), UrdfParseError, "malformed XML"),
        (lambda t: t.replace('<parent link="link1" />', '<parent link="nolink" />', 1), UrdfParseError, "Pinocchio"),
        (lambda t: t.replace('vjm:joint name="base_z" role="passive"', 'vjm:joint name="base_q" role="passive"'), JointNotFound, "base_q"),
        (lambda t: t.replace('frame="end"', 'frame="tip"'), FrameNotFound, "tip"),
        (lambda t: t.replace('role="passive"', 'role="floppy"'), RoleError, "floppy"),
        (lambda t: t.replace('<vjm:joint name="base_z" role="passive" position="-0.0" />', ""), RoleError, "no role"),
        (lambda t: t.replace('stiffness="1.0"', 'stiffness="-1.0"', 1), StiffnessMatrixError, "positive definite"),
        (lambda t: t.replace('stiffness="1.0"', 'stiffness="nan"', 1), Exception, "NaN"),
    ],
)
def test_malformed_vjm_urdf_raise_documented_errors(edit, exc, match):
    bad = edit(_good())
    assert bad != _good(), "the edit must change the file"
    with pytest.raises(exc, match=match):
        load_vjm(bad)


def test_spring_matrix_of_wrong_size_or_asymmetric_is_rejected():
    text = paper_model_urdf("b", "s", beam=PAPER_BEAM)
    start = text.index("<vjm:stiffness>") + len("<vjm:stiffness>")
    end = text.index("</vjm:stiffness>")
    nums = text[start:end].split()
    with pytest.raises(StiffnessMatrixError, match="expected 9"):
        load_vjm(text[:start] + " ".join(nums[:-1]) + text[end:])
    nums2 = list(nums)
    nums2[1] = repr(float(nums2[1]) + 1.0)
    with pytest.raises(StiffnessMatrixError, match="not symmetric"):
        load_vjm(text[:start] + " ".join(nums2) + text[end:])


def test_nan_inputs_are_refused():
    from vjm_pin import EquilibriumSolver

    vm = load_vjm(_good())
    with pytest.raises(InputError, match="NaN"):
        EquilibriumSolver(vm).solve([np.nan, 0, 0])
    with pytest.raises(InputError):
        EquilibriumSolver(vm).solve_wrench([0, np.inf, 0])
    with pytest.raises(InputError, match="position"):
        vm.with_positions({"qa1": float("nan")})
    with pytest.raises(InputError, match="outside the task"):  # paper-a-s is planar: task x y
        EquilibriumSolver(vm).solve([-0.1, 0, 0.05])


@pytest.mark.parametrize(
    "argv,match",
    [
        (["analyze", "no-such-model", "--deflection", "0", "0", "0"], "unknown model"),
        (["analyze", "paper-a-s", "--deflection", "nan", "0", "0"], "NaN"),
        (["analyze", "paper-a-s", "--deflection", "0", "0"], "3 or 6 numbers"),
        (["analyze", "paper-a-pi", "--wrench", "0", "0", "-0.5"], "not constrained"),
    ],
)
def test_cli_errors_print_one_line_and_exit_2(argv, match, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("vjm-pin: error:") and match in err


def test_cli_bad_file_exits_2(tmp_path, capsys):
    p = tmp_path / "broken.urdf"
    p.write_text("<robot><link name='a'>")
    assert main(["analyze", str(p), "--deflection", "0", "0", "0"]) == 2
    assert "malformed XML" in capsys.readouterr().err
