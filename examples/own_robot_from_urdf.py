"""Your own robot from a plain URDF, with springs built from datasheet values and beam sections.

A three-joint arm (waist, shoulder, elbow) is written as an ordinary URDF below. vjm_pin
turns it into a VJM model:

* every joint becomes an *actuator spring* whose stiffness (N·m/rad) you take from the gear
  datasheet (see docs/stiffness_values.md);
* the two arm links become 6-D *link springs*: the tip stiffness of a cantilever tube of the
  link's length (from the URDF joint origins), aluminium E = 70 GPa, ν = 0.33
  (:mod:`vjm_pin.model.beam`: axial EA/L, bending 12EI/L³ … inverted from the tip compliance).

Then a 200 N downward force is hung on the tool frame: the loaded equilibrium (eq. 5, force
prescribed), the deflection, and the loaded stiffness K_C (eq. 30) with and without the link
flexibility. Units: SI throughout (m, rad, N, N·m).

    python examples/own_robot_from_urdf.py [--out DIR]

Writes DIR/result.json (default: a new temporary folder) and prints a short report.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

import vjm_pin as vp
from vjm_pin.model.beam import Beam
from vjm_pin.model.registry import resolve_model

# A plain URDF: links and revolute joints, no VJM tags. Lengths: column 0.4 m, upper arm
# 0.5 m, forearm 0.4 m (the joint origins give the beam lengths).
ARM_URDF = """<?xml version="1.0"?>
<robot name="three_joint_arm">
  <link name="base_link"/>
  <link name="column"/>
  <link name="upper_arm"/>
  <link name="forearm"/>
  <link name="tool0"/>
  <joint name="waist" type="revolute">
    <parent link="base_link"/><child link="column"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3.14" upper="3.14" effort="100" velocity="1"/>
  </joint>
  <joint name="shoulder" type="revolute">
    <parent link="column"/><child link="upper_arm"/>
    <origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3.14" upper="3.14" effort="100" velocity="1"/>
  </joint>
  <joint name="elbow" type="revolute">
    <parent link="upper_arm"/><child link="forearm"/>
    <origin xyz="0.5 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3.14" upper="3.14" effort="100" velocity="1"/>
  </joint>
  <joint name="tool" type="fixed">
    <parent link="forearm"/><child link="tool0"/>
    <origin xyz="0.4 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"""

# Aluminium tube, Ø80 × 5 mm (beam length is taken from the URDF for each link).
TUBE = {"section": "tube", "outer_diameter": 0.08, "wall": 0.005, "E": 7.0e10, "nu": 0.33}

SPRINGS = {
    # Actuator (joint) stiffness, N·m/rad: the order of a size-25/32 harmonic drive at its
    # rated torque (datasheet torsional stiffness K3, see docs/stiffness_values.md).
    "actuators": {"waist": 2.0e5, "shoulder": 2.0e5, "elbow": 8.0e4},
    # Link flexibility: 6-D cantilever springs at each link tip (vjm_pin.model.beam).
    "links": {"upper_arm": {"beam": TUBE}, "forearm": {"beam": TUBE}},
}

LOAD = np.array([0.0, 0.0, -200.0])  # N, world axes: 200 N hanging on the tool frame
POSE = {"shoulder": -0.3, "elbow": 0.8}  # rad: upper arm raised, forearm pointing down a little


def analyse(urdf: Path, springs: dict) -> dict:
    """Equilibrium under LOAD, its deflection and loaded stiffness, for one spring spec."""
    vm = resolve_model(str(urdf), frame="tool0", q=POSE, springs=springs)
    eq = vp.EquilibriumSolver(vm).solve_wrench(np.concatenate([LOAD, np.zeros(3)]))
    if not eq.converged:
        raise SystemExit(f"no equilibrium: {eq.path}")
    k = vp.loaded_stiffness(vm, eq).stiffness  # 6×6, N/m, N/rad, N·m/rad; world axes
    # Stiffness along z with the end free in x and y: 1 / (compliance)_zz of the
    # translational block (a diagonal entry of K_C would hold x and y fixed instead).
    k_z_free = 1.0 / np.linalg.inv(k[:3, :3])[2, 2]
    return {
        "n_springs": int(vm.n_theta),
        "task": list(vm.task_names),
        "deflection_m": eq.deflection[:3].tolist(),
        "stable": bool(eq.stable),
        "k_z_free_N_per_m": float(k_z_free),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=None, help="output folder (default: a new temp folder)"
    )
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)
    urdf = out / "three_joint_arm.urdf"
    urdf.write_text(ARM_URDF)

    # What one link spring looks like: the beam's tip stiffness in the beam frame.
    beam = Beam.from_dict(TUBE, length=0.5)
    kb = beam.stiffness()
    print(
        f"upper-arm tube, 0.5 m: axial EA/L = {kb[0, 0]:.3e} N/m, lateral 12EI/L³ = {kb[1, 1]:.3e} N/m "
        f"(tip rotation held), bending 4EI/L = {kb[5, 5]:.3e} N·m/rad"
    )

    actuators_only = analyse(urdf, {"actuators": SPRINGS["actuators"]})
    # Closed form for rigid links, small load: a vertical force Fz makes the moment Fz·a at a
    # joint whose horizontal lever to the tool is a; the joint turns by Fz·a/k and the tool
    # drops by a·(Fz·a/k). The waist (vertical axis) does not move the tool vertically.
    qs, qe = POSE["shoulder"], POSE["elbow"]
    elbow_x = 0.5 * np.cos(qs)  # URDF: rotation about +y turns the link's x axis towards −z
    tool_x = elbow_x + 0.4 * np.cos(qs + qe)
    act = SPRINGS["actuators"]
    dz_closed = LOAD[2] * (tool_x**2 / act["shoulder"] + (tool_x - elbow_x) ** 2 / act["elbow"])
    with_links = analyse(urdf, SPRINGS)
    for label, r in (
        ("actuator springs only", actuators_only),
        ("actuators + link beams", with_links),
    ):
        dz = r["deflection_m"][2]
        print(
            f"{label:24s}: {r['n_springs']:2d} springs, tool deflection dz = {dz * 1e3:.4f} mm, "
            f"stiffness along z = {r['k_z_free_N_per_m'] / 1e3:.1f} N/mm, stable: {r['stable']}"
        )
    print(f"closed form, rigid links (small load): dz = {dz_closed * 1e3:.4f} mm")
    result = {
        "load_N": LOAD.tolist(),
        "actuators_only": actuators_only,
        "with_links": with_links,
        "beam_axial_stiffness_N_per_m": float(kb[0, 0]),
        "dz_closed_form_rigid_links_m": float(dz_closed),
    }
    (out / "result.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'result.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
