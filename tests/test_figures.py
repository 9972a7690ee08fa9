"""Paper-style snapshot figures (vjm_pin.viz.figures, ``view --png``): the panels are the
picked frames, the critical frame is one of them, the drawn links are where forward
kinematics puts them, unstable parts are red, and bad paths fail before any work."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from vjm_pin.kinematics.dead_loads import Load

COMPRESS = np.array([-1.0, 0, 0, 0, 0, 0])


@pytest.fixture(scope="module")
def c_anim():
    """The animation of the paper's Model C chain (S posture) under end compression."""
    from vjm_pin.cli.view import curve_animation, trace
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.viz.viewer import Animation, chain_geometry

    vm = resolve_model("paper-c-s")
    curve = trace(vm, COMPRESS, 0.05, 12)
    _, shown, _, kw = curve_animation(vm, curve, scale=5.0, n_frames=31)
    opts = {k: v for k, v in kw.items() if not k.startswith("_")}
    geom = chain_geometry(vm.model, vm.roles)
    return vm, Animation(vm.model, geom, shown, ghost_q=vm.reference, frame_name=vm.frame, **opts)


def _link_lines(ax):
    return [ln for ln in ax.get_lines() if ln.get_gid() == "link"]


def test_pick_frames_spreads_and_keeps_the_critical_frame():
    from vjm_pin.exceptions import InputError
    from vjm_pin.viz.figures import pick_frames

    for n, count, crit in ((91, 6, 37), (31, 4, 1), (31, 4, 30), (5, 9, 2), (40, 1, 17)):
        picks = pick_frames(n, count, crit)
        assert len(picks) == min(count, n) and crit in picks
        assert picks == sorted(set(picks)) and all(0 <= k < n for k in picks)
        if count >= 3 and n >= 3:
            assert picks[0] == 0 and picks[-1] == n - 1
    with pytest.raises(InputError):
        pick_frames(10, 0)


def test_panels_are_the_frames_and_links_sit_on_the_joints(c_anim):
    from vjm_pin.viz.figures import pick_frames, snapshot_figure

    vm, anim = c_anim
    crit = anim.critical_index
    assert crit is not None
    frames = pick_frames(len(anim.frames), 5, crit)
    fig, plane = snapshot_figure(anim, frames, title="t")
    try:
        panels = [ax for ax in fig.axes if ax.get_title()]
        assert len(panels) == 5
        assert [ax.get_title().startswith("CRITICAL") for ax in panels] == [
            k == crit for k in frames
        ]
        i, j = ("xyz".index(plane[0]), "xyz".index(plane[1]))
        assert panels[0].get_xlabel() == f"{plane[0]} (mm)"
        links = [g for g in anim.visual_model.geometryObjects if g.name.startswith("link:")]
        data = vm.model.createData()
        for ax, k in zip(panels, frames):
            pin.forwardKinematics(vm.model, data, anim.frames[k])
            lines = _link_lines(ax)
            assert len(lines) == len(links)
            for ln, go in zip(lines, links):
                ends = np.column_stack([ln.get_xdata(), ln.get_ydata()])
                base = data.oMi[go.parentJoint].translation[[i, j]] * 1e3
                # each segment starts at its parent joint's origin (mm)
                assert np.min(np.linalg.norm(ends - base, axis=1)) < 1e-6
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_unstable_parts_are_red_in_the_figure():
    """The portal frame past its sway buckling load: the last frame is unstable and its
    panel has red links (the columns and beam of the sway mode), the first panel none."""
    from vjm_pin.cli.view import mechanism_frames, mechanism_load_path
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.viz.figures import snapshot_figure
    from vjm_pin.viz.viewer import UNSTABLE_COLOR, Animation, chain_geometry

    vm = resolve_model("portal-frame")
    loads = [Load("top_left", [0, 0, -300.0]), Load("top_right", [0, 0, -300.0])]
    path = mechanism_load_path(vm, "loads", None, loads, n=5)
    assert path[-1].result.stable is False and path[0].result.stable is not False
    _, shown, _, kw = mechanism_frames(vm, path, "loads", loads)
    opts = {k: v for k, v in kw.items() if not k.startswith("_")}
    anim = Animation(vm.model, chain_geometry(vm.model, vm.roles, extra_frames=[vm.frame]),
                     shown, ghost_q=vm.reference, frame_name=vm.frame, **opts)
    fig, _ = snapshot_figure(anim, [0, 4])
    try:
        red = [
            sum(np.allclose(matplotlib_rgb(ln), UNSTABLE_COLOR[:3]) for ln in _link_lines(ax))
            for ax in fig.axes[:2]
        ]
        assert red[0] == 0 and red[1] >= 2
        assert "UNSTABLE" in fig.axes[1].get_title()
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def matplotlib_rgb(line):
    from matplotlib.colors import to_rgb

    return np.array(to_rgb(line.get_color()))


def test_view_png_cli_writes_the_figure_and_names_its_frames(tmp_path, capsys):
    from vjm_pin.cli import main

    png, pdf, page = tmp_path / "snap.png", tmp_path / "snap.pdf", tmp_path / "c.html"
    base = ["view", "paper-c-s", "--curve", "--direction", "-1", "0", "0",
            "--max-deflection", "0.05", "--steps", "12"]
    assert main([*base, "--png", str(png), "--snapshots", "4", "--html", str(page), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    snaps = out["snapshots"]
    assert len(snaps["frames"]) == 4 and snaps["path"] == str(png)
    assert out["critical_frame"] is not None
    assert snaps["critical_frame"] == out["critical_frame"] in snaps["frames"]
    assert all(0 <= k < len(out["frames"]) for k in snaps["frames"])
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # PDF by extension; without --html nothing is served
    assert main([*base, "--png", str(pdf), "--snapshots", "3"]) == 0
    assert "3 snapshots" in capsys.readouterr().out
    assert pdf.read_bytes()[:5] == b"%PDF-"


@pytest.mark.parametrize(
    "extra, word",
    [
        (["--png", "snap.txt"], "--png"),
        (["--png", "nofolder/snap.png"], "nofolder"),
        (["--snapshots", "3"], "--snapshots"),
        (["--png", "x.png", "--snapshots", "0"], "--snapshots"),
    ],
)
def test_view_png_bad_paths_are_one_line_errors(tmp_path, capsys, monkeypatch, extra, word):
    from vjm_pin.cli import main

    monkeypatch.chdir(tmp_path)
    keep = tmp_path / "x.png"
    keep.write_bytes(b"old")
    code = main(["view", "paper-c-s", "--wrench", "-1", "0", "0", *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("vjm-pin: error:") and word in err[0]
    assert keep.read_bytes() == b"old"
    assert not (tmp_path / "snap.txt").exists()
