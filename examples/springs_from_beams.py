"""Springs from beam sections: one boom, three cross-sections, a VJM URDF generated for each.

A plain URDF (below) holds a horizontal boom of length L on a shoulder joint about y. A spring
spec (docs/format.md, "Spring specification") gives the shoulder an actuator stiffness from a
gear datasheet and the boom a 6-D link spring computed from a beam section
(:mod:`vjm_pin.model.beam`: the inverse of the cantilever tip compliance; where such numbers
come from: docs/stiffness_values.md). ``generate_vjm`` writes the VJM URDF (six spring
joints at the boom tip, the ``<vjm:beam>`` kept as provenance), ``load_vjm`` reads it back,
and the tool is loaded by a small dead force (eq. 5, force prescribed).

Three aluminium sections of about the same area (mass per metre): a solid round bar, a
tube and an upright rectangle (side ``a`` along z). The tool deflection is compared with the
linear closed form ``dz = Fz (L³/(3 E I_y) + L²/k_a)``, ``dy = Fy L³/(3 E I_z)``.
Units: SI (m, rad, N, N·m, Pa).

The same from the command line, with the spec as YAML (written to DIR/spec_<section>.yaml):

    vjm-pin analyze DIR/boom.urdf --springs DIR/spec_tube.yaml --frame tool0 --wrench 0 20 -50

    python examples/springs_from_beams.py [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
import yaml

import vjm_pin as vp
from vjm_pin.model.beam import Beam
from vjm_pin.model.generator import generate_vjm

L = 0.8  # m, boom length (the joint origin of the tool frame below)
BOOM_URDF = f"""<?xml version="1.0"?>
<robot name="boom">
  <link name="base_link"/>
  <link name="boom"/>
  <link name="tool0"/>
  <joint name="shoulder" type="revolute">
    <parent link="base_link"/><child link="boom"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3.14" upper="3.14" effort="100" velocity="1"/>
  </joint>
  <joint name="tool" type="fixed">
    <parent link="boom"/><child link="tool0"/>
    <origin xyz="{L} 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"""

ALUMINIUM = {"E": 7.0e10, "nu": 0.33}  # Pa; density 2700 kg/m³ for the mass per metre
DENSITY = 2700.0
SECTIONS = {  # about 1200 mm² each
    "circle": {"section": "circle", "diameter": 0.040},
    "tube": {"section": "tube", "outer_diameter": 0.060, "wall": 0.0075},
    "rectangle": {"section": "rectangle", "a": 0.060, "b": 0.020},  # a along z (upright)
}
K_SHOULDER = 2.0e4  # N·m/rad, actuator (gear) torsional stiffness, datasheet order of magnitude
FORCE = np.array([0.0, 20.0, -50.0])  # N at the tool, world axes: sideways and down


def spring_spec(section: dict) -> dict:
    """The spring spec: task frame and components, the actuator, the boom as a beam (its
    length from the URDF). The task is given: without it ``vjm-pin analyze --springs`` keeps
    only the components the rigid joints move (here z)."""
    return {
        "frame": "tool0",
        "task": ["x", "y", "z", "rx", "ry", "rz"],
        "actuators": {"shoulder": K_SHOULDER},
        "links": {"boom": {"beam": {**section, **ALUMINIUM}}},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="output folder (default: a new temporary one)")
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="vjm-example-"))
    out.mkdir(parents=True, exist_ok=True)
    plain = out / "boom.urdf"
    plain.write_text(BOOM_URDF)

    results = {}
    for name, section in SECTIONS.items():
        spec = spring_spec(section)
        (out / f"spec_{name}.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
        vjm_urdf = out / f"boom_{name}_vjm.urdf"
        vjm_urdf.write_text(generate_vjm(plain, spec))  # plain URDF + spec -> VJM URDF text
        vm = vp.load_vjm(vjm_urdf)

        props = Beam.from_dict({**section, **ALUMINIUM}, length=L).properties  # A, I_y, I_z, J
        eq = vp.EquilibriumSolver(vm).solve_wrench(np.concatenate([FORCE, np.zeros(3)]))
        k_c = vp.loaded_stiffness(vm, eq).stiffness  # (6, 6) loaded K_C, world axes at the tool
        e = ALUMINIUM["E"]
        dz_closed = FORCE[2] * (L**3 / (3 * e * props.iy) + L**2 / K_SHOULDER)
        dy_closed = FORCE[1] * L**3 / (3 * e * props.iz)
        results[name] = {
            "area_m2": props.area,
            "I_y_m4": props.iy,
            "I_z_m4": props.iz,
            "n_springs": int(vm.n_theta),
            "deflection_m": eq.deflection[:3].tolist(),
            "dz_closed_form_m": dz_closed,
            "dy_closed_form_m": dy_closed,
            # stiffness along z with the tool free in the other five components
            "k_z_free_N_per_m": float(1.0 / np.linalg.inv(k_c)[2, 2]),
            "stable": bool(eq.stable),
        }
        print(
            f"{name:9s}: A = {props.area * 1e6:6.0f} mm² ({props.area * DENSITY:.2f} kg/m), "
            f"I_y = {props.iy * 1e12:9.0f} mm⁴, I_z = {props.iz * 1e12:9.0f} mm⁴, {vm.n_theta} springs; "
            f"tool dz = {eq.deflection[2] * 1e3:7.4f} mm (closed form {dz_closed * 1e3:7.4f}), "
            f"dy = {eq.deflection[1] * 1e3:7.4f} mm (closed form {dy_closed * 1e3:7.4f}), "
            f"k_z = {results[name]['k_z_free_N_per_m'] / 1e3:.2f} N/mm, stable: {eq.stable}"
        )
    stiffest = max(results, key=lambda n: results[n]["k_z_free_N_per_m"] / results[n]["area_m2"])
    print(f"stiffest in z for its mass: {stiffest}")
    summary = {
        "length_m": L,
        "k_shoulder_N_m_per_rad": K_SHOULDER,
        "force_N": FORCE.tolist(),
        "E_Pa": ALUMINIUM["E"],
        "sections": results,
    }
    (out / "beams.json").write_text(json.dumps(summary, indent=1))
    print(
        f"written {out / 'beams.json'} and the generated URDFs; e.g. "
        f"vjm-pin analyze {plain} --springs {out / 'spec_tube.yaml'} --frame tool0 --wrench 0 20 -50"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
