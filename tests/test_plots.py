"""Plots (vjm_pin.viz.plots): pre-buckling inset, stiffness against load, map heat maps."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from vjm_pin.analysis.curve import trace_curve  # noqa: E402
from vjm_pin.model.registry import resolve_model  # noqa: E402
from vjm_pin.viz import plots  # noqa: E402


@pytest.fixture(scope="module")
def column_curve():
    # Model B, straight posture: buckles at ~1 mm, a tiny deflection against the range traced
    return trace_curve(resolve_model("paper-b-s"), [-1, 0, 0], 0.5, 40)


def test_inset_zooms_on_the_branch_before_the_critical_point(column_curve):
    assert column_curve.critical, "the straight column must buckle"
    fig, ax = plt.subplots()
    plots.plot_curve(column_curve, ax)
    (ins,) = ax.child_axes
    c = min(column_curve.critical, key=lambda c: abs(c.deflection))
    lo, hi = ins.get_xlim()
    assert lo <= c.deflection <= hi and hi - lo < 0.5 * np.ptp(ax.get_xlim())
    fig2, ax2 = plt.subplots()
    plots.plot_curve(column_curve, ax2, inset=False)
    assert not ax2.child_axes
    plt.close("all")


def test_stiffness_panel_plots_the_points_stiffness_against_their_force(column_curve):
    fig, ax = plt.subplots()
    plots.plot_stiffness(column_curve, ax)
    x, y = ax.lines[0].get_data()
    pts = [p for p in column_curve.points if p.stable and np.isfinite(p.stiffness)]
    want = {(round(p.force, 9), round(p.stiffness, 3)) for p in pts}
    got = {(round(a, 9), round(b, 3)) for a, b in zip(x, y) if np.isfinite(a) and np.isfinite(b)}
    assert got == want
    assert "N/m" in ax.get_ylabel() and "[N]" in ax.get_xlabel()
    plt.close("all")


def test_curve_plot_file_has_two_panels(column_curve, tmp_path):
    out = tmp_path / "c.png"
    plots.save_curve_plot(column_curve, out)
    img = plt.imread(out)
    assert img.shape[1] > 1.8 * img.shape[0]  # two panels side by side


def _fake_map(poses, k, p0, status):
    n = len(poses)
    return SimpleNamespace(
        model="m", frame="tip", joints=("a", "b"), poses=poses, p0=p0,
        deflection=np.zeros((n, 6)), k_min=k, status=np.array(status), wrench=np.zeros(6),
    )


def test_map_heat_map_puts_each_pose_in_its_cell_and_respects_the_floor(tmp_path, monkeypatch):
    a, b = np.linspace(0, 1, 4), np.linspace(-1, 1, 3)
    poses = np.array([(x, y) for x in a for y in b])
    k = 1e3 * (1 + poses[:, 0] + 2 * (poses[:, 1] + 1))
    p0 = np.column_stack([poses[:, 0], poses[:, 1], poses[:, 1]])  # z < 0 for b = -1
    status = ["ok"] * len(poses)
    status[5] = "no-equilibrium"
    res = _fake_map(poses, k, p0, status)
    seen = {}
    real = plots._joint_heat_map

    def spy(fig, ax, result, grid, ok):
        real(fig, ax, result, grid, ok)
        seen["img"] = ax.collections[0].get_array()
        seen["ok"] = ok.copy()

    monkeypatch.setattr(plots, "_joint_heat_map", spy)
    plots.save_map_plot(res, tmp_path / "m.png")
    assert (tmp_path / "m.png").stat().st_size > 0
    ok = seen["ok"]
    assert not ok[5] and not ok[poses[:, 1] < 0].any() and ok.sum() == len(poses) - 1 - 4
    img = np.ma.filled(seen["img"].reshape(len(b), len(a)), np.nan)
    for (x, y), kk, good in zip(poses, k, ok):
        v = img[list(b).index(y), list(a).index(x)]
        assert (v == pytest.approx(kk)) if good else np.isnan(v)


def test_grid_detection():
    assert plots._grid_shape(np.array([[0, 0], [0, 1], [1, 0], [1, 1.0]])) is not None
    assert plots._grid_shape(np.array([[0, 0], [0, 1], [1, 0.0]])) is None  # incomplete
    assert plots._grid_shape(np.zeros((4, 3))) is None  # three joints: no heat map
