"""Tests of ``vjm-pin view`` and ``vjm-pin demo`` (in-process ``main([...])``), and the exported
Model C S-posture buckling page rendered in headless Chromium (skipped when no chromium binary
is installed)."""

from __future__ import annotations

import importlib.util
import re

import numpy as np
import pytest

from vjm_pin.cli import main
from vjm_pin.cli.view import curve_page
from vjm_pin.model.registry import resolve_model
from vjm_pin.solver import EquilibriumSolver
from vjm_pin.analysis.curve import trace_curve
from vjm_pin.viz.viewer import default_scale, magnify

from .browser import chromium, screenshot_frames

MODEL = "paper-c-s"
DIRECTION = np.array([-1.0, 0, 0, 0, 0, 0])


@pytest.fixture(scope="module")
def model_c():
    return resolve_model(MODEL)


@pytest.fixture(scope="module")
def c_curve(model_c):
    return trace_curve(model_c, DIRECTION, 0.05, 15)


# ----------------------------------------------------------------------------- view
def test_view_deflection_page_magnifies_small_deformation(model_c, tmp_path, capsys):
    """A pre-buckling deflection of 0.05 mm on a 3 m chain is invisible at scale 1: the
    default scale magnifies it and the page says by how much."""
    page = tmp_path / "d.html"
    assert main(["view", MODEL, "--deflection", "-0.00005", "0", "0", "--html", str(page)]) == 0
    out = capsys.readouterr().out
    scale = float(re.search(r"deformation ×(\S+);", out).group(1))
    text = page.read_text(encoding="utf-8")
    assert f"deformation ×{scale:g}" in text
    assert scale >= 100, out
    # the displayed largest displacement is then a visible fraction of the robot's size
    res = EquilibriumSolver(model_c).solve(np.array([-5e-5, 0, 0]))
    assert default_scale(model_c.model, model_c.reference, [res.x]) == scale
    # 1-2-5 rounding down: the magnified deformation needs at most 2x more to be "visible" ...
    shown = magnify(model_c.reference, res.x, scale)
    assert default_scale(model_c.model, model_c.reference, [shown]) <= 2.0
    # ... and a deformation that is already visible is never shrunk
    big = magnify(model_c.reference, res.x, 10 * scale)
    assert default_scale(model_c.model, model_c.reference, [big]) == 1.0


def test_view_explicit_scale_is_stated(tmp_path, capsys):
    page = tmp_path / "w.html"
    args = [
        "view",
        MODEL,
        "--deflection",
        "-0.0001",
        "0",
        "0",
        "--scale",
        "250",
        "--html",
        str(page),
    ]
    assert main(args) == 0
    assert "deformation ×250" in capsys.readouterr().out
    assert "deformation ×250" in page.read_text(encoding="utf-8")


def test_view_curve_page(tmp_path, capsys):
    page = tmp_path / "c.html"
    args = ["view", MODEL, "--curve", "--direction", "-1", "0", "0", "--max-deflection", "0.05"]
    assert main([*args, "--steps", "10", "--html", str(page)]) == 0
    out = capsys.readouterr().out
    assert str(page) in out
    text = page.read_text(encoding="utf-8")
    assert "past the critical point F_cr" in text  # the label of the critical frame
    assert "UNSTABLE" not in out


@pytest.mark.parametrize(
    "args, words",
    [
        (["--curve", "--max-deflection", "0.05"], "--direction"),
        (["--curve", "--direction", "-1", "0", "0"], "--max-deflection"),
        (["--curve", "--direction", "-1", "0", "0", "--max-deflection", "-1"], "--max-deflection"),
        (["--deflection", "-0.0001", "0", "0", "--scale", "-2"], "--scale"),
        (["--deflection", "1", "0"], "--deflection"),
    ],
)
def test_view_bad_input(args, words, tmp_path, capsys):
    assert main(["view", MODEL, *args, "--html", str(tmp_path / "x.html")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vjm-pin: error:") and words in err and err.count("\n") == 1


# ----------------------------------------------------------------------------- demo
def test_demo_writes_page_and_reports_buckling(tmp_path, capsys, c_curve):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    m = re.search(
        r"critical point: force (\S+) N at deflection (\S+) mm; stiffness before (\S+) N/m, after (\S+) N/m",
        out,
    )
    assert m, out
    force, defl_mm, k_before, k_after = map(float, m.groups())
    # independent of the demo's step count: the critical force of a coarse trace (refined by
    # bisection) agrees, and the chain loses almost all axial stiffness after buckling
    assert force == pytest.approx(abs(c_curve.critical[0].force), rel=1e-3)
    assert force / (defl_mm * 1e-3) == pytest.approx(k_before, rel=1e-2)  # linear before buckling
    assert k_after < 0.01 * k_before
    html = tmp_path / "curve.html"
    assert html.is_file() and str(html.resolve()) in out
    if importlib.util.find_spec("vjm_pin.viz.plots") is not None:
        png = tmp_path / "curve.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(png.resolve()) in out


def test_no_command_points_to_demo(capsys):
    assert main([]) == 0
    assert "vjm-pin demo" in capsys.readouterr().out


# ----------------------------------------------------------------------------- browser


def _green(img: np.ndarray) -> np.ndarray:
    """Pixels of the stable robot's green links, as shaded by meshcat."""
    r, g, b = (img[..., i].astype(int) for i in range(3))
    return (g > 100) & (g > r + 50) & (g > b + 40)


def test_browser_model_c_buckling_page(model_c, c_curve, tmp_path):
    """The exported Model C S-curve page, seen from the side (camera along −y: z is up in the
    picture, the chain's plane is edge-on): straight just before the critical frame, visibly
    bowed out of the plane (z) after it."""
    browser = chromium()
    if browser is None:
        pytest.skip("no chromium binary on PATH (apt-get install chromium)")

    page = tmp_path / "c.html"
    cp = curve_page(model_c, c_curve, path=page, camera_direction=(0.0, -1.0, 0.0))
    assert cp.critical_frame is not None and cp.critical_frame >= 1
    before, last = cp.critical_frame - 1, cp.frames - 1
    img = screenshot_frames(browser, page, (before, last), tmp_path)
    for k, a in img.items():
        assert a.std() > 10, f"frame {k}: blank screenshot"
    g0, g1 = _green(img[before]), _green(img[last])
    assert g0.sum() > 1500 and g1.sum() > 1500, (g0.sum(), g1.sum())  # the robot is there
    # out-of-plane jump: the straight chain is a thin horizontal band, the buckled one spans
    # many more rows (z displacement of the middle joints)
    rows0, rows1 = np.nonzero(g0.any(axis=1))[0], np.nonzero(g1.any(axis=1))[0]
    height0, height1 = rows0.max() - rows0.min(), rows1.max() - rows1.min()
    assert height1 > 3 * height0 and height1 > height0 + 40, (height0, height1)
    diff = np.abs(img[before].astype(int) - img[last].astype(int)).max(axis=2)
    assert (diff > 30).mean() > 0.01


def test_view_takes_the_robot_options(tmp_path, capsys):
    """view accepts --q/--frame like analyze: a posed ur5 page is written."""
    out = tmp_path / "ur5.html"
    assert main(["view", "ur5", "--q", "elbow_joint=1.2", "--wrench", "0", "0", "-100", "--html", str(out)]) == 0
    assert out.is_file() and "stable" in capsys.readouterr().out
    assert main(["view", "ur5", "--frame", "nope", "--wrench", "0", "0", "-1", "--html", str(out)]) == 2
