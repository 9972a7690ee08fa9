"""Random VJM chains for the tests, built through the generator (never the network)."""

from __future__ import annotations

import numpy as np

from vjm_pin import generate_vjm, load_vjm

DOF_SETS = (["x", "y", "z", "rx", "ry", "rz"], ["x", "y", "rz"], ["y", "z", "rx"], ["rz"])


def random_spd(rng, n, lo=1.0, hi=10.0):
    a = rng.standard_normal((n, n))
    q, _ = np.linalg.qr(a)
    return q @ np.diag(rng.uniform(lo, hi, n)) @ q.T


def random_chain_urdf(rng, n_joints=5, prismatic_prob=0.3) -> str:
    parts = ['<robot name="random">', '  <link name="base"/>']
    for i in range(n_joints):
        jt = "prismatic" if rng.random() < prismatic_prob else "revolute"
        axis = rng.standard_normal(3)
        axis /= np.linalg.norm(axis)
        xyz = rng.uniform(-0.3, 0.3, 3) + np.array([0.4, 0, 0]) * (i > 0)
        rpy = rng.uniform(-1, 1, 3)
        parent = "base" if i == 0 else f"l{i}"
        parts.append(f'  <link name="l{i + 1}"/>')
        parts.append(
            f'  <joint name="j{i + 1}" type="{jt}"><parent link="{parent}"/><child link="l{i + 1}"/>'
            f'<origin xyz="{" ".join(repr(float(v)) for v in xyz)}" rpy="{" ".join(repr(float(v)) for v in rpy)}"/>'
            f'<axis xyz="{" ".join(repr(float(v)) for v in axis)}"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        )
    tip = rng.uniform(0.2, 0.5, 3)
    parts.append('  <link name="tool"/>')
    parts.append(
        f'  <joint name="tool_joint" type="fixed"><parent link="l{n_joints}"/><child link="tool"/>'
        f'<origin xyz="{" ".join(repr(float(v)) for v in tip)}" rpy="0.1 0.2 0.3"/></joint>'
    )
    parts.append("</robot>")
    return "\n".join(parts)


def random_vjm(
    seed: int,
    *,
    n_joints=5,
    n_passive=1,
    task=("x", "y", "z", "rx", "ry", "rz"),
    link_springs=2,
    spring_dofs=None,
    kscale=1.0,
):
    """A random chain: ``n_passive`` passive joints, the other joints actuated with 1-D
    springs, ``link_springs`` links with 6-D/3-D/1-D springs (random SPD matrices),
    random pose and rest values."""
    rng = np.random.default_rng(seed)
    urdf = random_chain_urdf(rng, n_joints)
    joints = [f"j{i + 1}" for i in range(n_joints)]
    passive = list(rng.choice(joints, size=n_passive, replace=False)) if n_passive else []
    actuators = {j: float(rng.uniform(5, 50) * kscale) for j in joints if j not in passive}
    positions = {j: float(rng.uniform(-1, 1)) for j in joints}
    links = {}
    for k, link in enumerate(
        rng.choice([f"l{i + 1}" for i in range(n_joints)], size=link_springs, replace=False)
    ):
        dofs = spring_dofs if spring_dofs is not None else DOF_SETS[k % len(DOF_SETS)]
        links[str(link)] = {
            "stiffness": (random_spd(rng, len(dofs), 20, 200) * kscale).tolist(),
            "dofs": list(dofs),
        }
    spec = {
        "frame": "tool",
        "task": list(task),
        "passive": [str(p) for p in passive],
        "actuators": actuators,
        "positions": positions,
        "links": links,
    }
    return load_vjm(generate_vjm(urdf, spec))


def ur5_link_springs():
    """ur5 (example-robot-data) with 6-D springs of aluminium tubes in its five links (skipped
    without example-robot-data)."""
    import pytest

    pytest.importorskip("example_robot_data")
    from vjm_pin.model.robots import build_robot

    links = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link")
    beam = {"section": "tube", "outer_diameter": 0.09, "wall": 0.005, "E": 7.0e10, "nu": 0.33}
    return build_robot("ur5", springs={"links": {ln: {"beam": dict(beam)} for ln in links}}).vm


def warm_sequence(vm, direction, top, steps, **options):
    """Warm-started solves along ``direction`` up to ``top`` in ``steps`` (each from the previous
    equilibrium), by an ``EquilibriumSolver(vm, **options)``."""
    from vjm_pin.solver.equilibrium import EquilibriumSolver

    s = EquilibriumSolver(vm, **options)
    prev = s.solve(top / steps * direction)
    out = [prev]
    for t in np.linspace(top / steps, top, steps)[1:]:
        prev = s.solve(t * direction, x0=prev.x, wrench0=prev.wrench)
        out.append(prev)
    return out
