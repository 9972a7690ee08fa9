"""Every script in examples/ runs (as a user would: a subprocess, an output folder) and its
output has the property the example is about, checked against numbers computed here."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCRIPTS = sorted(p.name for p in EXAMPLES.glob("*.py"))


def run_example(name: str, out: Path, *args: str) -> str:
    """Run examples/NAME with ``--out OUT``; return its stdout (fails on a non-zero exit)."""
    proc = subprocess.run(
        [sys.executable, str(EXAMPLES / name), "--out", str(out), *args],
        check=False,
        capture_output=True,
        text=True,
        timeout=300,
        cwd=out,
    )
    assert proc.returncode == 0, f"{name} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def test_every_example_is_checked_here():
    """A new example must get a test below (the list of scripts is not hard-coded elsewhere)."""
    checked = {
        "own_robot_from_urdf.py",
        "buckling_curve.py",
        "parallel_orthoglide.py",
        "workspace_map_dask.py",
        "closed_loop_portal_frame.py",
        "springs_from_beams.py",
        "four_bar_coupler_load.py",
    }
    assert set(SCRIPTS) == checked, (
        f"examples without a test (or tests without an example): {set(SCRIPTS) ^ checked}"
    )


def test_own_robot_from_urdf(tmp_path):
    run_example("own_robot_from_urdf.py", tmp_path)
    assert (tmp_path / "three_joint_arm.urdf").is_file()
    r = json.loads((tmp_path / "result.json").read_text())
    rigid, flexible = r["actuators_only"], r["with_links"]
    # Rigid links: the deflection is the closed form Σ Fz a²/k within the large-deflection
    # correction (deflection/lever ~ 1e-3).
    dz, dz_closed = rigid["deflection_m"][2], r["dz_closed_form_rigid_links_m"]
    assert dz < 0 and dz_closed < 0
    assert dz == pytest.approx(dz_closed, rel=5e-3), "actuator-spring deflection vs closed form (m)"
    # Link beams add compliance: the tool sinks further and the stiffness drops.
    assert flexible["deflection_m"][2] < dz
    assert flexible["n_springs"] == rigid["n_springs"] + 12  # two 6-D link springs
    assert 0 < flexible["k_z_free_N_per_m"] < rigid["k_z_free_N_per_m"]
    # The stiffness along z is the load over the deflection to first order (small load).
    assert rigid["k_z_free_N_per_m"] == pytest.approx(-200.0 / dz, rel=2e-2)
    # The printed beam stiffness is the axial EA/L of the Ø80 x 5 mm tube, 0.5 m, E = 70 GPa.
    area = math.pi * (0.08**2 - 0.07**2) / 4
    assert r["beam_axial_stiffness_N_per_m"] == pytest.approx(7.0e10 * area / 0.5, rel=1e-9)
    assert rigid["stable"] and flexible["stable"]


def test_buckling_curve(tmp_path):
    run_example("buckling_curve.py", tmp_path)
    assert (tmp_path / "curve.png").stat().st_size > 1000
    d = json.loads((tmp_path / "curve.json").read_text())
    forces = [c["force_N"] for c in d["critical"]]
    assert forces and all(math.isfinite(f) and f > 0 for f in forces)
    # Model A, S posture buckles at Kθ/L = 1 N (paper §6.1.3) ...
    assert forces[0] == pytest.approx(1.0, rel=1e-3)
    # ... and then follows the stable branch of eq. (35), F = Kθ/L · φ/sin φ, φ = acos(1 − Δ/2L).
    s = np.array(d["deflection_m"])
    f = np.array(d["force_N"])
    bent = s > 1e-3
    phi = np.arccos(1.0 - s[bent] / 2.0)
    np.testing.assert_allclose(f[bent], phi / np.sin(phi), rtol=1e-6)
    assert all(d["stable"])


def test_parallel_orthoglide(tmp_path):
    run_example("parallel_orthoglide.py", tmp_path)
    d = json.loads((tmp_path / "orthoglide.json").read_text())
    direction = np.array(d["direction"])
    k0 = d["unloaded_stiffness_along_N_per_m"]
    assert math.isfinite(k0) and k0 > 0
    moves = []
    for row in d["loads"]:
        w = np.array(row["wrench_N"])
        # The legs carry the applied wrench between them (statics of the platform).
        np.testing.assert_allclose(row["leg_wrench_sum_N"], w, atol=1e-6 * np.abs(w).max())
        assert len(row["legs"]) == 3 and row["stable"]
        moves.append(float(direction @ np.array(row["deflection_m"])[:3]))
        # A compressive load softens the legs (negative geometric stiffness).
        assert 0 < row["stiffness_along_N_per_m"] < k0
    assert all(m > 0 for m in moves) and np.all(np.diff(moves) > 0)
    # Far below buckling the displacement is the load over the unloaded stiffness (within 1 %).
    first = d["loads"][0]
    assert moves[0] == pytest.approx(first["force_N"] / k0, rel=1e-2)


def test_workspace_map_dask(tmp_path):
    pytest.importorskip("dask.distributed", reason="the dask extra is not installed")
    run_example("workspace_map_dask.py", tmp_path, "--poses", "8")
    assert (tmp_path / "map.png").stat().st_size > 1000
    with open(tmp_path / "map.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 8
    summary = json.loads((tmp_path / "map.json").read_text())
    assert summary["dask_equals_serial"] is True
    # Re-solve two mapped poses here, directly (eq. 5 under the wrench), and compare.
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.solver import EquilibriumSolver

    vm = resolve_model("ur5")
    wrench = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])
    for row in [r for r in rows if r["status"] == "ok"][:2]:
        pose = {j: float(row[j]) for j in summary["joints"]}
        eq = EquilibriumSolver(vm.with_positions(pose)).solve_wrench(wrench)
        mapped = np.array([float(row[k]) for k in ("dx_m", "dy_m", "dz_m")])
        np.testing.assert_allclose(mapped, eq.deflection[:3], rtol=1e-6, atol=1e-12)
        assert float(row["k_along_N_per_m"]) > 0


def test_closed_loop_portal_frame(tmp_path):
    run_example("closed_loop_portal_frame.py", tmp_path)
    d = json.loads((tmp_path / "portal_frame.json").read_text())
    # k and h read here from the bundled model, independently of the script.
    from vjm_pin.model.registry import resolve_model

    vm = resolve_model("portal-frame")
    k = float(np.diag(vm.K_theta).min())
    assert np.allclose(np.diag(vm.K_theta), k) and d["k_N_m_per_rad"] == pytest.approx(k)
    h = float(vm.model.jointPlacements[vm.model.getJointId("corner_tl")].translation[2])
    # Sway buckling load per column of the closed form (total potential, small φ): 2k/h.
    assert d["P_cr_N"] == pytest.approx(2.0 * k / h, rel=1e-8)
    assert d["above_critical"]["stable"] is False
    assert d["above_critical"]["stable_end_held"] is True
    # Each push curve against dΠ/dφ = 0 of Π = 2kφ² − F h sin φ − 2Ph(1 − cos φ), s = h sin φ.
    assert len(d["curves"]) >= 2
    for c in d["curves"]:
        s, f, p = np.array(c["sway_m"]), np.array(c["force_N"]), c["P_N"]
        assert s[-1] > 0.1 * h
        phi = np.arcsin(s / h)
        f_closed = (4 * k * phi - 2 * p * h * np.sin(phi)) / (h * np.cos(phi))
        np.testing.assert_allclose(f, f_closed, rtol=1e-8, atol=1e-8 * np.abs(f_closed).max())
        # sway stiffness of the straight frame: (4k − 2Ph)/h²
        assert c["stiffness_N_per_m"][0] == pytest.approx((4 * k - 2 * p * h) / h**2, rel=1e-6)


def test_springs_from_beams(tmp_path):
    run_example("springs_from_beams.py", tmp_path)
    d = json.loads((tmp_path / "beams.json").read_text())
    length, e, k_a = d["length_m"], d["E_Pa"], d["k_shoulder_N_m_per_rad"]
    fy, fz = d["force_N"][1], d["force_N"][2]
    # Second moments from the textbook formulas (not from vjm_pin.model.beam).
    inertia = {
        "circle": (math.pi * 0.04**4 / 64,) * 2,
        "tube": (math.pi * (0.06**4 - 0.045**4) / 64,) * 2,
        "rectangle": (0.02 * 0.06**3 / 12, 0.06 * 0.02**3 / 12),  # (I_y, I_z), a = 60 mm along z
    }
    assert set(d["sections"]) == set(inertia)
    for name, (iy, iz) in inertia.items():
        r = d["sections"][name]
        assert r["I_y_m4"] == pytest.approx(iy, rel=1e-12) and r["I_z_m4"] == pytest.approx(
            iz, rel=1e-12
        )
        assert r["n_springs"] == 7 and r["stable"]  # the actuator + one 6-D link spring
        dx, dy, dz = r["deflection_m"]
        # Linear cantilever + actuator closed form; the difference is the large-deflection
        # correction, of the order of the tip rotation squared.
        assert dz == pytest.approx(fz * (length**3 / (3 * e * iy) + length**2 / k_a), rel=1e-3)
        assert dy == pytest.approx(fy * length**3 / (3 * e * iz), rel=1e-3)
        assert abs(dx) < 1e-2 * abs(dz)
        k_lin = 1.0 / (length**3 / (3 * e * iy) + length**2 / k_a)
        assert r["k_z_free_N_per_m"] == pytest.approx(k_lin, rel=1e-2)
        text = (tmp_path / f"boom_{name}_vjm.urdf").read_text()
        assert "<vjm:beam" in text and 'section="' + name + '"' in text


def test_four_bar_coupler_load(tmp_path):
    run_example("four_bar_coupler_load.py", tmp_path)
    d = json.loads((tmp_path / "four_bar.json").read_text())
    # A Load at the coupler point (task free) and the same force as the task wrench: one equilibrium.
    np.testing.assert_allclose(
        d["deflection_load_m"], d["deflection_task_wrench_m"], rtol=1e-7, atol=1e-12
    )
    dx, dz = np.array(d["deflection_load_m"])[[0, 2]]
    # Small load: the linear response K_C⁻¹F within the large-deflection correction.
    np.testing.assert_allclose([dx, dz], d["deflection_linear_m"], rtol=2e-2)
    # Statics about the base pin (no moment there): load + pivot reaction + crank spring = 0.
    m = d["moments_about_base_N_m"]
    assert abs(m["load"]) > 0.1 and abs(m["crank"]) > 0.01
    assert m["load"] + m["pivot"] + m["crank"] == pytest.approx(0.0, abs=1e-8 * abs(m["load"]))
    assert d["stable"]
