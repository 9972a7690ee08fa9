"""Mesh names of URDFs resolved (vjm_pin.model.meshes): package://, ROS_PACKAGE_PATH, missing."""

from __future__ import annotations

from pathlib import Path

from vjm_pin.model.meshes import resolve_meshes
from vjm_pin.model.robots import robot_source

URDF = """<robot name="r">
  <link name="a"><visual><geometry><mesh filename="package://my_pkg/meshes/a.stl"/></geometry></visual></link>
  <link name="b"><visual><geometry><mesh filename='meshes/b.stl' scale="1 1 1"/></geometry></visual></link>
  <link name="c"><visual><geometry><mesh filename="package://gone/c.stl"/></geometry></visual></link>
</robot>"""


def _tree(tmp_path: Path) -> Path:
    ws = tmp_path / "ws"
    (ws / "my_pkg" / "meshes").mkdir(parents=True)
    (ws / "my_pkg" / "meshes" / "a.stl").write_text("solid a\nendsolid a\n")
    (tmp_path / "robot" / "meshes").mkdir(parents=True)
    (tmp_path / "robot" / "meshes" / "b.stl").write_text("solid b\nendsolid b\n")
    return ws


def test_package_dir_and_urdf_folder_resolve_and_missing_are_named(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    ws = _tree(tmp_path)
    res = resolve_meshes(URDF, [ws], urdf_dir=tmp_path / "robot")
    assert res.found["package://my_pkg/meshes/a.stl"] == str((ws / "my_pkg/meshes/a.stl").resolve())
    assert res.found["meshes/b.stl"] == str((tmp_path / "robot/meshes/b.stl").resolve())
    assert res.missing == ("package://gone/c.stl",)
    assert str((ws / "my_pkg/meshes/a.stl").resolve()) in res.urdf
    assert "package://gone/c.stl" in res.urdf  # a missing mesh is left as it was
    assert "scale=\"1 1 1\"" in res.urdf


def test_ros_package_path_is_searched(tmp_path, monkeypatch):
    ws = _tree(tmp_path)
    without = resolve_meshes(URDF, [])
    assert "package://my_pkg/meshes/a.stl" in without.missing
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"/nonexistent:{ws}")
    res = resolve_meshes(URDF, [])
    assert "package://my_pkg/meshes/a.stl" in res.found


def test_example_robot_data_meshes_all_resolve():
    src = robot_source("ur5")
    text = Path(src.urdf).read_text()
    res = resolve_meshes(text, [], urdf_dir=Path(src.urdf).parent)
    assert res.found and not res.missing
    assert all(Path(p).is_file() for p in res.found.values())
