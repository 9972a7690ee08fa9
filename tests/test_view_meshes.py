"""The robot's own meshes in ``vjm-pin view``: ``package://`` names found in ``--package-dir``
folders are drawn as meshes; a mesh that is not found is named in a warning and the robot
is drawn with primitives, which the page's legend and the JSON say."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

MESH = "package://my_pkg/meshes/link.stl"


def _stl(path: Path, half: float = 0.01) -> None:
    """A closed cube of side 2·half (ASCII STL)."""
    v = np.array([[x, y, z] for x in (-half, half) for y in (-half, half) for z in (-half, half)])
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    lines = ["solid cube"]
    for f in faces:
        n = np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]])
        nx, ny, nz = n / np.linalg.norm(n)
        lines.append(f" facet normal {nx:g} {ny:g} {nz:g}\n  outer loop")
        lines += [" ".join(["   vertex", *(f"{c:g}" for c in v[i])]) for i in f]
        lines.append("  endloop\n endfacet")
    path.write_text("\n".join(lines + ["endsolid cube\n"]))


URDF = f"""<robot name="arm">
  <link name="base"><visual><geometry><mesh filename="{MESH}"/></geometry></visual></link>
  <link name="l1"><visual><origin xyz="0 0 0.2"/><geometry><mesh filename="{MESH}" scale="1 1 20"/></geometry></visual>
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="l2"><visual><origin xyz="0 0 0.15"/><geometry><mesh filename="{MESH}" scale="1 1 15"/></geometry></visual>
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.4"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="jt" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0 0 0.3"/></joint>
</robot>
"""


@pytest.fixture
def arm(tmp_path, monkeypatch):
    """(URDF path, package folder holding my_pkg) in separate trees; ROS_PACKAGE_PATH unset."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    ws = tmp_path / "ws"
    (ws / "my_pkg" / "meshes").mkdir(parents=True)
    _stl(ws / "my_pkg" / "meshes" / "link.stl")
    (tmp_path / "robot").mkdir()
    urdf = tmp_path / "robot" / "arm.urdf"
    urdf.write_text(URDF)
    return urdf, ws


def _setup(text: str) -> dict:
    return json.loads(re.search(r"var setup = (\{.*?\});\n", text, re.DOTALL).group(1))


def test_load_visuals_finds_package_meshes_and_names_missing_ones(arm):
    from vjm_pin.model.registry import resolve
    from vjm_pin.viz.viewer import load_visuals

    urdf, ws = arm
    vm, _ = resolve(str(urdf))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing to warn about
        vis = load_visuals(vm.model, vm.urdf, [ws])
    assert vis.geometry is not None and not vis.missing and vis.note is None
    want = str((ws / "my_pkg/meshes/link.stl").resolve())
    assert [g.meshPath for g in vis.geometry.geometryObjects] == [want] * 3
    with pytest.warns(UserWarning) as rec:
        gone = load_visuals(vm.model, vm.urdf, [])
    assert gone.geometry is None and gone.missing == (MESH,)
    texts = [str(w.message) for w in rec]
    assert len(texts) == 1 and MESH in texts[0] and "primitives" in texts[0]
    assert "not found" in gone.note


def test_view_draws_meshes_with_package_dir_and_says_when_primitives_replace_them(
    arm, tmp_path, capsys
):
    from vjm_pin.cli import main

    urdf, ws = arm
    page = tmp_path / "mesh.html"
    argv = ["view", str(urdf), "--wrench", "10", "0", "0", "--html", str(page), "--json"]
    assert main([*argv, "--package-dir", str(ws)]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert out["meshes"] == {"drawn": "meshes", "missing": [], "note": None}
    assert "warning" not in cap.err
    text = page.read_text(encoding="utf-8")
    assert "not found" not in " ".join(e["text"] for e in _setup(text)["legend"])

    prim = tmp_path / "prim.html"
    assert main([*argv[:-3], "--html", str(prim), "--json"]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert out["meshes"]["drawn"] == "primitives" and out["meshes"]["missing"] == [MESH]
    warn = [ln for ln in cap.err.splitlines() if ln.startswith("vjm-pin: warning:")]
    assert len(warn) == 1 and MESH in warn[0]
    legend = [e["text"] for e in _setup(prim.read_text(encoding="utf-8"))["legend"]]
    assert any("not found" in t and "primitives" in t for t in legend)


def test_view_bad_package_dir_is_a_one_line_error(arm, tmp_path, capsys):
    from vjm_pin.cli import main

    urdf, _ = arm
    page = tmp_path / "x.html"
    code = main(["view", str(urdf), "--wrench", "1", "0", "0", "--html", str(page),
                 "--package-dir", str(tmp_path / "nope")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--package-dir" in err[0] and "nope" in err[0]
    assert not page.exists()
