"""Write the Orthoglide VJM models ``models/urdf/orthoglide-q{0..4}.urdf`` (folded parallelogram),
``orthoglide-coupled-q{0..4}.urdf`` (folded, coupler rotation spring),
``orthoglide-2bar-q{0..4}.urdf`` (both bars modelled, two chains) and
``orthoglide-loop-q{0..4}.urdf`` (both bars modelled, parallelograms as true closed loops).

Paper: Pashkevich, Klimchik, Chablat, MMT 46 (2011), §6.2, Table 2 ("the seed paper").
Every number below carries its source or derivation; ``docs/orthoglide_sources.md`` (§ numbers
quoted as "src §x") gives the full argument, ``docs/orthoglide.md`` the results.
``tests/test_orthoglide.py`` (and ``tests/test_orthoglide_loops.py`` for the loop variant)
regenerates the files and fails if a committed file differs.

Architecture (seed §6.2; src §2.1): three identical P–R–Pa–R legs, actuated prismatic joints
along the mutually orthogonal base axes e_1, e_2, e_3, a foot (cantilever bracket) carrying the
first passive revolute R1 at A_i = ρ_i e_i, a parallelogram (two bars, two axles), a passive
revolute R2 to the platform. R1, R2 are along the axle y_i = e_{i+1} (cyclic choice, src §2.1);
the parallelogram joints along n_i = e_i × y_i = e_{i+2}.

Bars: the section is not published; it is **designed** so that a leg buckles (Euler, the
parallelogram pinned by R1 and R2) at the leg force of Table 2's Q0 critical point
(:func:`bar_outer_diameter`), and each bar is modelled by ``BAR_SEGMENTS`` VJM segments so that
the chain between the pins can bow. With this, every work point buckles within the paper's
range and the critical forces of Q1…Q4 are predictions (docs/orthoglide.md).

Variants
--------
``orthoglide-qK``  (folded, as the seed paper: "the limb stiffness is described by an equivalent
    5-d.o.f. virtual spring"). Kinematics R1(y)·Pa1(z)·T_x(L)·[spring]·Pa2(z)·R2(y): the
    parallelogram as two independent revolutes, so n = 4 passive joints per leg, which gives the
    seed paper's "(n+6)×(n+6) = 10×10" (its eq. 10 remark). The equivalent spring of the two
    bars is derived below (src §3.3); its in-plane coupler rotation φz (d²EA/2L) is in series
    with the passive Pa2 in this realisation and is therefore dropped: the spring is 4-D
    (x, z, φx, φy). vjm_pin has no mimic joints, so the exact parallelogram constraint
    (coupler angle = −Pa1) cannot be written in one serial chain.
``orthoglide-coupled-qK`` (folded, with the fifth spring component): as ``folded``, but Pa1 and
    Pa2 form a spring pair on the coupler rotation Pa1 + Pa2 with the stiffness (d²/2)EA/L of the
    5-D spring (+ a residual ε = 1e-6 of it on each joint, since the pair must be positive
    definite): the mimic constraint of the parallelogram, made elastic with its physical
    stiffness. The leg then has two passive joints (R1, R2) and a near-free spring direction
    (the parallelogram mobility, stiffness ε).
``orthoglide-2bar-qK`` (closed loop through the platform): each parallelogram as two serial
    legs, one per bar (at ±d/2 along the axle), both ending at the platform. Each bar has its own
    4-D cantilever spring (x, z, φx, φy; in-plane y, φz are the pins). The actuator and the foot,
    shared by the two bars in the real leg, are split into two halves (k_a/2, K_F/2): exact when
    the two bars carry equal forces, softer otherwise (the superposition of paper §5 cannot
    close a loop at the foot). The in-plane coupler rotation is resisted by the two bars'
    differential stretching, which the folded variant lacks.
``orthoglide-loop-qK`` (true loops, explicit closures; :func:`_loop_leg`): one shared actuator
    and foot per leg, then R1; from the first axle two bars at ±d/2 along it, each with passive
    Pa1, Pa2 at its ends and its own ``BAR_SEGMENTS`` segment springs (x, z, φx, φy). Bar a runs
    into the second axle (which carries R2); bar b's end is held on the second axle by the
    ``<vjm:closure>`` ``legK_parallelogram`` in all six components. Leg 1 carries the platform
    (task frame :data:`PLATFORM_FRAME`); legs 2 and 3 are held on it by the closures
    ``legK_platform`` (all six components). No ``<vjm:leg>``: the file is a mechanism for
    :class:`~vjm_pin.solver.mechanism.MechanismSolver`. Closure rank on the free coordinates
    30 of 30 rows (none redundant; on the passive joints alone 18, the rigid linkage being
    over-constrained). ``orthoglide_urdf(point, "folded", platform="closures")`` writes the
    folded model the same way (for the comparison, ``scripts/compare_orthoglide_loops.py``).

Usage: ``python scripts/make_orthoglide.py [--out models/urdf]``
"""

from __future__ import annotations

import argparse
import itertools
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from vjm_pin.model.beam import Beam

NS = "urn:vjm-pin:1"

# ---------------------------------------------------------------- geometry (src §2.2–2.4)
#: Workspace cube side (m): seed §6.2, "dexterous cubical workspace 200×200×200 mm³".
CUBE = 0.200
#: Bar length L (m): Q1, Q2 are the cube vertices on the bisector where the transmission factors
#: reach the design bounds [0.5, 2.0] (seed §6.2): s₊ = L/√6 (a = s/h = 1/2) and s₋ = −L/√18
#: (a = −1/4); s₊ − s₋ = 200 mm → L = 0.2/(1/√6 + 1/√18) = 0.31058 m (docs/orthoglide.md, src §2.3).
L_BAR = CUBE / (1 / math.sqrt(6) + 1 / math.sqrt(18))
S_PLUS = L_BAR / math.sqrt(6)  # +0.12679 m, the stiff vertex (src §2.4)
S_MINUS = -L_BAR / math.sqrt(18)  # −0.07320 m, the vertex near the flat singularity (src §2.4)
#: Work points (m), base frame with origin at the isotropic point Q0 (src §2.4, Table 2 labels:
#: Q1 = s₊ vertex (stiffest), Q2 = s₋ vertex (near the flat singularity det = 0 at s = −L/√6);
#: Q3, Q4: the two classes of the other vertices, {2 at s₊, 1 at s₋} and {2 at s₋, 1 at s₊}).
POINTS = {
    "q0": (0.0, 0.0, 0.0),
    "q1": (S_PLUS, S_PLUS, S_PLUS),
    "q2": (S_MINUS, S_MINUS, S_MINUS),
    "q3": (S_PLUS, S_PLUS, S_MINUS),
    "q4": (S_MINUS, S_MINUS, S_PLUS),
}

# ---------------------------------------------------------------- compliances (src §3.3, tag D)
#: Aluminium alloy (assumption, src §3.3): E = 70 GPa, G = 26 GPa.
E_AL, G_AL = 70e9, 26e9
#: Foot: cantilever bracket l_f = 100 mm, solid 40 × 20 mm (40 across, 20 along the actuator
#: axis), along the parallelogram normal n_i (assumption, src §2.5 and §3.3; not published).
FOOT = Beam(0.100, "rectangle", {"a": 0.020, "b": 0.040}, E_AL, G_AL)
#: Table 2's critical force at the isotropic point Q0 (N). At Q0 the three bars are along the
#: actuator axes e_i, so a force F along the bisector u loads each leg with F/√3 (statics,
#: docs/orthoglide.md "Critical forces"): the seed paper's Q0 buckling is a leg force of
#: 4.65 kN/√3 = 2.685 kN.
F_CR_TABLE2_Q0 = 4.65e3
#: Wall thickness of the bar tubes relative to their outer diameter (assumption: the proportion
#: of the Ø20 × 2 mm tube first assumed in src §3.3).
BAR_WALL_RATIO = 0.1
#: Number of VJM segments per bar (beyond the paper's single spring): each segment ends in the
#: spring of a bar of length L/k, so the chain between the pins R1, R2 can bow and converges to
#: the Euler column as k grows (1/k², docs/paper_reproduction.md, subdivision study).
BAR_SEGMENTS = 8


def bar_outer_diameter() -> float:
    """Outer diameter (m) of the bar tubes, **derived** (not published, src §3.3): the
    parallelogram is pinned at both ends by R1 and R2 (axes along the axle) and its two bars
    bend together in the plane normal to the axle, so a leg buckles at Euler's load
    π²·2EI/L² (pinned–pinned, two bars). Setting that equal to the leg force of Table 2's Q0
    critical point, F_cr/√3 (statics at Q0), gives I = F_cr L²/(2√3 π² E); with wall = D/10,
    I = (π/64)(1 − 0.8⁴) D⁴ → D ≈ 8.97 mm (Ø8.97 × 0.90 mm aluminium tubes). This is the
    second calibration on Q0 (the first is k_a); every other point's critical force is then a
    prediction."""
    inertia = F_CR_TABLE2_Q0 / math.sqrt(3) * L_BAR**2 / (2 * math.pi**2 * E_AL)
    shape = math.pi / 64 * (1 - (1 - 2 * BAR_WALL_RATIO) ** 4)
    return (inertia / shape) ** 0.25


def bar_beam(length: float = L_BAR) -> Beam:
    """One bar (or one segment of it) as a :class:`~vjm_pin.model.beam.Beam` (aluminium tube)."""
    d = bar_outer_diameter()
    return Beam(length, "tube", {"outer_diameter": d, "wall": BAR_WALL_RATIO * d}, E_AL, G_AL)


#: The whole bar (length L).
BAR = bar_beam()
#: Distance between the two bars along the axle (m): 80 mm (assumption, src §2.5).
D_AXLE = 0.080
#: Actuator stiffness (N/m), calibrated (src §3.3): at Q0 every bar is along its actuator, so the
#: stiffness along the bisector is the axial stiffness of one leg, Table 2's 3.23 kN/mm, hence
#: 1/k_a = 1/3.23e6 − c_foot(along e_i) − c_bars(axial); see :func:`calibrated_actuator`.
K_TABLE2_Q0 = 3.23e6
#: Platform offset r (m): leg i's R2 joint sits at P − r·e_i, on the platform side facing its
#: actuator. Not published (src §2.5); 0 in the bundled models. An offset along e_i only shifts
#: ρ_i by the constant r (src §2.2), and at Q0 every leg force still passes through P, so Q0's
#: unloaded stiffness and the k_a calibration do not depend on it; under load it gives the leg
#: forces a lever arm on the platform rotation (a compressed leg adds −P·r(1 + r/L) to the
#: rotational stiffness about the axes normal to it). Kept as a parameter for sensitivity
#: studies; the buckling of Table 2 does not need it (the legs buckle, docs/orthoglide.md).
PLATFORM_R = 0.0
#: Perpendicular platform offset (m): R2 at P + rp·n_i and A_i = ρ e_i + rp n_i, so the position
#: kinematics is unchanged; rp > 0 makes the planar chain foot–bar–platform arm a Π, rp < 0 a Z
#: (seed §6.2 speaks of S/Z → Π transitions). Not published; 0 in the bundled models.
PLATFORM_RP = 0.0
#: Residual stiffness of the parallelogram mobility in the coupled variant, relative to the
#: coupler stiffness (a numerical stand-in for a mimic joint, which vjm_pin lacks).
EPS_MOBILITY = 1e-6


def bar_spring(length: float = L_BAR) -> np.ndarray:
    """4×4 stiffness of one bar (x, z, φx, φy) of ``length`` (m) at its platform-end, bar frame
    (N/m, N, N·m/rad): the cantilever tip stiffness of :class:`~vjm_pin.model.beam.Beam` without the
    in-plane (y, φz) rows, which the parallelogram's pins (axes along z) release."""
    keep = [0, 2, 3, 4]
    return np.linalg.inv(bar_beam(length).compliance()[np.ix_(keep, keep)])


def parallelogram_spring(length: float = L_BAR) -> np.ndarray:
    """Equivalent spring of the parallelogram at the coupler centre, bar frame (src §3.3).

    Two bars at r_j = (0, ±d/2, 0); each bar's 6×6 end stiffness K_j (the 4×4 of
    :func:`bar_spring`, zero for the pinned y and φz) is moved to the centre by
    δp_j = δp + δφ × r_j, K = Σ T_jᵀ K_j T_j. Result (x, y, z, φx, φy, φz): K_yy = 0 (the
    parallelogram mobility, dropped → the 5-D spring of [49]); K_xx = 2EA/L, K_φzφz = (d²/2)EA/L,
    K_φxφx = 2GJ/L + (d²/2)·12EI/L³. Returns the 6×6 (y row zero)."""
    kb = np.zeros((6, 6))
    keep = [0, 2, 3, 4]
    kb[np.ix_(keep, keep)] = bar_spring(length)
    k = np.zeros((6, 6))
    for sgn in (1.0, -1.0):
        r = np.array([0.0, sgn * D_AXLE / 2, 0.0])
        t = np.eye(6)
        t[:3, 3:] = -np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
        k += t.T @ kb @ t
    return 0.5 * (k + k.T)


def folded_spring(length: float = L_BAR) -> np.ndarray:
    """The 4-D spring (x, z, φx, φy) of the folded variant: the 5-D equivalent spring without φz,
    which is in series with the passive Pa2 joint here (see the module docstring)."""
    keep = [0, 2, 3, 4]
    return parallelogram_spring(length)[np.ix_(keep, keep)]


def foot_axial_compliance() -> float:
    """Foot compliance along the actuator axis (m/N): the foot frame has z along e_i, so it is the
    cantilever bending term L³/(3EI_y) (src §3.3: 1.786e−4 mm/N)."""
    return float(FOOT.compliance()[2, 2])


def calibrated_actuator() -> float:
    """k_a (N/m) such that one leg's axial stiffness at Q0 is Table 2's 3.23 kN/mm: actuator,
    foot (bending along e_i) and the two bars (axial, 2EA/L) in series (src §3.3: ≈ 8.98 kN/mm)."""
    c_bars = 1.0 / parallelogram_spring()[0, 0]
    return 1.0 / (1.0 / K_TABLE2_Q0 - foot_axial_compliance() - c_bars)


# ---------------------------------------------------------------- URDF writer
E3 = np.eye(3)


def _f(v) -> str:
    return " ".join(repr(round(float(x), 15) + 0.0) for x in np.atleast_1d(v))


def _rpy(r: np.ndarray) -> np.ndarray:
    """URDF rpy of a rotation matrix (R = Rz(y) Ry(p) Rx(r))."""
    import pinocchio as pin

    return np.asarray(pin.rpy.matrixToRpy(np.asarray(r, float)))


def leg_angles(p, i: int) -> tuple[float, float, float]:
    """Actuator position ρ_i (m) and the unloaded passive angles (R1 = a, Pa1 = b) of leg i at
    platform point p: A_i = ρ_i e_i on the negative side, |P − A_i| = L (src §2.2); with the bar
    unit vector w in the leg frame (e_i, y_i, n_i), R_y(a)R_z(b)e_x = w gives b = asin(w_y),
    a = atan2(−w_z, w_x); Pa2 = −b and R2 = −a keep the platform orientation."""
    p = np.asarray(p, float)
    j, k = (i + 1) % 3, (i + 2) % 3
    rho = p[i] - math.sqrt(L_BAR**2 - p[j] ** 2 - p[k] ** 2)
    w = (p - rho * E3[i]) / L_BAR
    wl = np.array([w[i], w[j], w[k]])  # leg frame axes: e_i, y_i = e_{i+1}, n_i = e_{i+2}
    return rho, math.atan2(-wl[2], wl[0]), math.asin(wl[1])


def leg_coefficients(point: str, direction=(1.0, 1.0, 1.0)) -> np.ndarray:
    """Axial leg forces per newton of platform force along ``direction`` (positive: the leg is
    pulled, tension), by rigid-body statics: every bar passes through the platform point, so a
    force F·d is carried as Σ f_i w_i with w_i = (P − A_i)/L the bar directions.
    At Q0 the bars are the base axes and f_i = 1/√3 along the bisector (docs/orthoglide.md,
    "Critical forces and leg statics")."""
    p = np.asarray(POINTS[point], float)
    w = np.column_stack([(p - leg_angles(p, i)[0] * E3[i]) / L_BAR for i in range(3)])
    d = np.asarray(direction, float)
    return np.linalg.solve(w, d / np.linalg.norm(d))


class _Writer:
    def __init__(self, name: str):
        self.root = ET.Element("robot", {"name": name, "xmlns:vjm": NS})
        ET.SubElement(self.root, "link", {"name": "base"})
        self.tags: list[ET.Element] = []

    def joint(self, name, kind, parent, xyz=(0, 0, 0), rpy=(0, 0, 0), axis=None):
        ET.SubElement(self.root, "link", {"name": name + "_link"})
        j = ET.SubElement(self.root, "joint", {"name": name, "type": kind})
        ET.SubElement(j, "parent", {"link": parent})
        ET.SubElement(j, "child", {"link": name + "_link"})
        ET.SubElement(j, "origin", {"xyz": _f(xyz), "rpy": _f(rpy)})
        if axis is not None:
            ET.SubElement(j, "axis", {"xyz": _f(axis)})
            lim = "6.283185307179586" if kind == "revolute" else "1.0"
            ET.SubElement(
                j, "limit", {"lower": "-" + lim, "upper": lim, "effort": "1", "velocity": "1"}
            )
        return name + "_link"

    def tag(self, tag, attrib, text=None, children=()):
        el = ET.Element(f"vjm:{tag}", attrib)
        if text is not None:
            el.text = text
        for c in children:
            el.append(c)
        self.tags.append(el)

    def spring(self, name, parent, dofs, k):
        """Virtual spring joints along the parent frame's axes (T_s(θ) of eq. 34) and its group."""
        names = []
        for d in dofs:
            axis = E3["xyz".index(d[-1])]
            kind = "prismatic" if len(d) == 1 else "revolute"
            parent = self.joint(f"{name}_{d}", kind, parent, axis=axis)
            names.append(f"{name}_{d}")
            self.tag("joint", {"name": f"{name}_{d}", "role": "spring"})
        st = ET.Element("vjm:stiffness")
        st.text = _f(np.asarray(k, float).ravel())
        self.tag("spring", {"name": name, "link": parent, "joints": " ".join(names)}, None, [st])
        return parent

    def text(self) -> str:
        for t in self.tags:
            self.root.append(t)
        ET.indent(self.root)
        return ET.tostring(self.root, encoding="unicode") + "\n"


def _actuator_and_foot(w: _Writer, name: str, i: int, p, k_act: float, k_foot, r: float, rp: float):
    """Actuated slider, foot with its 6-D tip spring and the fixed turn to the leg frame
    (e_i, y_i, n_i) at A_i. Returns (link, a, b): the leg-frame link at A_i and the unloaded
    R1 and Pa1 angles (:func:`leg_angles` at P − r·e_i)."""
    e, y, n = E3[i], E3[(i + 1) % 3], E3[(i + 2) % 3]
    rho, a, b = leg_angles(np.asarray(p, float) - r * e, i)
    lf = FOOT.length
    # actuator: the carriage sits at (rp − l_f) n_i + ρ e_i, so A_i = ρ e_i + rp n_i (constant
    # offsets: the kinematics of src §2.2 holds); actuated joint with its spring (rest = ρ)
    link = w.joint(f"{name}_act", "prismatic", "base", xyz=(rp - lf) * n, axis=e)
    # the stroke: ρ over the corners of the workspace cube (what a map samples)
    corners = [np.array(c) for c in itertools.product((S_MINUS, S_PLUS), repeat=3)]
    rhos = [leg_angles(c - r * e, i)[0] for c in corners]
    lim = w.root.find(f"joint[@name='{name}_act']/limit")
    lim.set("lower", repr(float(min(rhos))))
    lim.set("upper", repr(float(max(rhos))))
    w.tag(
        "joint",
        {
            "name": f"{name}_act",
            "role": "actuated",
            "position": repr(float(rho)),
            "stiffness": repr(float(k_act)),
        },
    )
    # foot: from the carriage to A_i along n_i; foot frame x_f = n_i, z_f = e_i (20 mm side),
    # y_f = e_i × n_i; its 6-D tip spring at A_i (src §4.1 row 3)
    r_foot = np.column_stack([n, np.cross(e, n), e])
    link = w.joint(f"{name}_foot", "fixed", link, xyz=lf * n, rpy=_rpy(r_foot))
    link = w.spring(f"{name}_foot_s", link, ("x", "y", "z", "rx", "ry", "rz"), k_foot)
    # leg frame (e_i, y_i, n_i) at A_i
    r_leg = np.column_stack([e, y, n])
    link = w.joint(f"{name}_to_leg", "fixed", link, rpy=_rpy(r_foot.T @ r_leg))
    return link, a, b


def _leg(
    w: _Writer,
    name: str,
    i: int,
    p,
    k_act: float,
    k_foot,
    bar_y: float,
    k_bar,
    r: float,
    rp: float = 0.0,
    k_coupler: float | None = None,
    platform: str = "leg",
):
    """One serial leg (or one bar of a two-bar leg when ``bar_y`` ≠ 0) ending at the platform.

    The leg's R2 joint is at P − r·e_i + rp·n_i (platform offsets, :data:`PLATFORM_R`,
    :data:`PLATFORM_RP`). With ``k_coupler`` the parallelogram joints Pa1, Pa2 are a spring
    pair of stiffness ``k_coupler·[[1, 1], [1, 1]] + ε I`` on the coupler rotation Pa1 + Pa2
    (see :data:`EPS_MOBILITY`), else two passive joints. ``platform``: ``"leg"`` writes the
    ``<vjm:leg>`` shorthand, ``"carry"``/``"close"`` end the leg as :func:`_platform_end`."""
    link, a, b = _actuator_and_foot(w, name, i, p, k_act, k_foot, r, rp)
    link = w.joint(f"{name}_R1", "revolute", link, axis=(0, 1, 0))
    w.tag("joint", {"name": f"{name}_R1", "role": "passive", "position": repr(a)})
    if bar_y:
        link = w.joint(f"{name}_axle1", "fixed", link, xyz=(0, bar_y, 0))
    pa_role = {"role": "spring"} if k_coupler else {"role": "passive", "position": repr(b)}
    link = w.joint(f"{name}_Pa1", "revolute", link, axis=(0, 0, 1))
    w.tag("joint", {"name": f"{name}_Pa1", **pa_role})
    # the bar in BAR_SEGMENTS rigid segments, each ending in its spring (k_bar: one segment's)
    for j in range(1, BAR_SEGMENTS + 1):
        link = w.joint(f"{name}_bar{j}", "fixed", link, xyz=(L_BAR / BAR_SEGMENTS, 0, 0))
        link = w.spring(f"{name}_bar{j}_s", link, ("x", "z", "rx", "ry"), k_bar)
    link = w.joint(f"{name}_Pa2", "revolute", link, axis=(0, 0, 1))
    pa_role = {"role": "spring"} if k_coupler else {"role": "passive", "position": repr(-b)}
    w.tag("joint", {"name": f"{name}_Pa2", **pa_role})
    if k_coupler:
        k = k_coupler * np.ones((2, 2)) + EPS_MOBILITY * k_coupler * np.eye(2)
        st = ET.Element("vjm:stiffness")
        st.text = _f(k.ravel())
        rest = ET.Element("vjm:rest")
        rest.text = _f((b, -b))
        w.tag(
            "spring",
            {"name": f"{name}_coupler", "link": link, "joints": f"{name}_Pa1 {name}_Pa2"},
            None,
            [st, rest],
        )
    if bar_y:
        link = w.joint(f"{name}_axle2", "fixed", link, xyz=(0, -bar_y, 0))
    link = w.joint(f"{name}_R2", "revolute", link, axis=(0, 1, 0))
    w.tag("joint", {"name": f"{name}_R2", "role": "passive", "position": repr(-a)})
    # the end link has the leg-frame orientation (e_i, y_i, n_i) at the reference:
    # P = R2 + r e_i − rp n_i
    if platform == "leg":
        w.tag("leg", {"name": name, "frame": link, "offset": _f((r, 0.0, -rp))})
    else:
        _platform_end(w, name, i, link, r, rp, platform == "carry")


def _bar(w: _Writer, name: str, link: str, b: float, k_bar) -> str:
    """One parallelogram bar from ``link`` (its first axle, leg-frame orientation): passive Pa1
    (axis n_i, unloaded b), ``BAR_SEGMENTS`` rigid segments each ending in its 4-D spring
    (x, z, φx, φy; ``k_bar`` one segment's), passive Pa2 (−b). Returns the link after Pa2 (the
    second axle's orientation)."""
    link = w.joint(f"{name}_Pa1", "revolute", link, axis=(0, 0, 1))
    w.tag("joint", {"name": f"{name}_Pa1", "role": "passive", "position": repr(b)})
    for j in range(1, BAR_SEGMENTS + 1):
        link = w.joint(f"{name}_bar{j}", "fixed", link, xyz=(L_BAR / BAR_SEGMENTS, 0, 0))
        link = w.spring(f"{name}_bar{j}_s", link, ("x", "z", "rx", "ry"), k_bar)
    link = w.joint(f"{name}_Pa2", "revolute", link, axis=(0, 0, 1))
    w.tag("joint", {"name": f"{name}_Pa2", "role": "passive", "position": repr(-b)})
    return link


#: Components of every closure of the closed variants (all six: each loop has springs in every
#: direction, so no row is redundant; docs/orthoglide.md "Loop variant").
CLOSURE_COMPONENTS = "x y z rx ry rz"
#: Task frame of the closed variants: the platform point P, world-aligned at the reference.
PLATFORM_FRAME = "platform_link"


def _platform_end(w: _Writer, name: str, i: int, link: str, r: float, rp: float, carry: bool):
    """End of leg ``name`` at the platform, with explicit closures (no ``<vjm:leg>``).

    ``link`` (after R2) has the leg-frame orientation at the reference; a fixed joint puts a
    world-aligned frame at the platform point P = R2 + r e_i − rp n_i. The carrying leg (leg 1)
    names it :data:`PLATFORM_FRAME` (the rigid platform and the task frame); every other leg's
    frame ``<leg>_at_platform_link`` is held on it by a ``<vjm:closure>`` in all six components
    (the platform is one rigid body)."""
    r_leg = np.column_stack([E3[i], E3[(i + 1) % 3], E3[(i + 2) % 3]])
    jname = "platform" if carry else f"{name}_at_platform"
    end = w.joint(jname, "fixed", link, xyz=(r, 0.0, -rp), rpy=_rpy(r_leg.T))
    if not carry:
        w.tag(
            "closure",
            {
                "name": f"{name}_platform",
                "frame_a": end,
                "frame_b": PLATFORM_FRAME,
                "components": CLOSURE_COMPONENTS,
            },
        )


def _loop_leg(
    w: _Writer, name: str, i: int, p, k_act: float, k_foot, k_bar, r: float, rp: float, carry: bool
):
    """One leg with its parallelogram as a true loop (variant ``loop``).

    Actuator, foot and R1 as :func:`_leg`; the link after R1 is the first axle. Bar ``a`` runs
    from the axle point +d/2·y_i (Pa1a, segments, Pa2a) into the second axle: the link
    ``<leg>_axle2`` (at −d·y_i from bar a's end, i.e. where bar b ends) and, d/2 back, its centre
    carrying R2 and the platform end. Bar ``b`` runs from −d/2·y_i (Pa1b, segments, Pa2b); its
    end link coincides with ``<leg>_axle2`` at the reference and is held on it by the closure
    ``<leg>_parallelogram`` in all six components (a rigid axle). Both bars have their own springs (the same 4-D segment springs as the
    two-bar variant) and passive revolutes at both ends, so the coupler rotation, the
    parallelogram constraint and the bars' differential stretching/bending come out of the
    loop instead of being folded into one spring."""
    link, a, b = _actuator_and_foot(w, name, i, p, k_act, k_foot, r, rp)
    axle1 = w.joint(f"{name}_R1", "revolute", link, axis=(0, 1, 0))
    w.tag("joint", {"name": f"{name}_R1", "role": "passive", "position": repr(a)})
    half = D_AXLE / 2
    link = w.joint(f"{name}a_axle1", "fixed", axle1, xyz=(0, half, 0))
    link = _bar(w, f"{name}a", link, b, k_bar)
    axle2 = w.joint(f"{name}_axle2", "fixed", link, xyz=(0, -2 * half, 0))
    # ``axle2`` is the second axle at bar b's end point (−d/2·y_i); R2 sits at its centre
    link = w.joint(f"{name}b_axle1", "fixed", axle1, xyz=(0, -half, 0))
    bend = _bar(w, f"{name}b", link, b, k_bar)
    w.tag(
        "closure",
        {
            "name": f"{name}_parallelogram",
            "frame_a": bend,
            "frame_b": axle2,
            "components": CLOSURE_COMPONENTS,
        },
    )
    link = w.joint(f"{name}_axle2c", "fixed", axle2, xyz=(0, half, 0))
    link = w.joint(f"{name}_R2", "revolute", link, axis=(0, 1, 0))
    w.tag("joint", {"name": f"{name}_R2", "role": "passive", "position": repr(-a)})
    _platform_end(w, name, i, link, r, rp, carry)


def orthoglide_urdf(
    point: str,
    variant: str = "folded",
    r: float = PLATFORM_R,
    rp: float = PLATFORM_RP,
    platform: str = "leg",
) -> str:
    """URDF text of the Orthoglide at work point ``point`` (q0…q4); ``variant`` ``folded``,
    ``coupled``, ``2bar`` or ``loop`` (see the module docstring); ``r``, ``rp`` the platform
    offsets (m). ``platform``: ``"leg"`` joins the legs with the ``<vjm:leg>`` shorthand
    (``docs/parallel.md``), ``"closures"`` carries the platform on leg 1 and holds the other
    legs on it with explicit ``<vjm:closure>`` elements (task frame :data:`PLATFORM_FRAME`, all
    six components); the ``loop`` variant always uses closures."""
    if platform not in ("leg", "closures"):
        raise ValueError(f"unknown platform {platform!r}; choose 'leg' or 'closures'")
    if variant == "loop":
        platform = "closures"
    if point not in POINTS:
        raise ValueError(f"unknown point {point!r}; choose one of {sorted(POINTS)}")
    p = POINTS[point]
    k_a = calibrated_actuator()
    k_foot = FOOT.stiffness()
    names = {"folded": "orthoglide", "coupled": "orthoglide-coupled", "2bar": "orthoglide-2bar"}
    ends = ["carry", "close", "close"] if platform == "closures" else ["leg"] * 3
    if variant in ("folded", "coupled"):
        w = _Writer(f"{names[variant]}-{point}" + ("-closed" if platform == "closures" else ""))
        k_c = parallelogram_spring()[5, 5] if variant == "coupled" else None
        for i in range(3):
            k_bar = folded_spring(L_BAR / BAR_SEGMENTS)
            _leg(w, f"leg{i + 1}", i, p, k_a, k_foot, 0.0, k_bar, r, rp, k_c, ends[i])
    elif variant == "2bar":
        if platform != "leg":
            raise ValueError("the 2bar variant is written with <vjm:leg> only")
        w = _Writer(f"orthoglide-2bar-{point}")
        for i in range(3):
            for tag, sgn in (("a", 1.0), ("b", -1.0)):
                _leg(
                    w,
                    f"leg{i + 1}{tag}",
                    i,
                    p,
                    k_a / 2,
                    k_foot / 2,
                    sgn * D_AXLE / 2,
                    bar_spring(L_BAR / BAR_SEGMENTS),
                    r,
                    rp,
                )
    elif variant == "loop":
        w = _Writer(f"orthoglide-loop-{point}")
        k_seg = bar_spring(L_BAR / BAR_SEGMENTS)
        for i in range(3):
            _loop_leg(w, f"leg{i + 1}", i, p, k_a, k_foot, k_seg, r, rp, ends[i] == "carry")
    else:
        raise ValueError(
            f"unknown variant {variant!r}; choose 'folded', 'coupled', '2bar' or 'loop'"
        )
    if platform == "closures":
        w.tag("task", {"frame": PLATFORM_FRAME, "components": CLOSURE_COMPONENTS})
    else:
        w.tag("platform", {"name": "platform", "components": "x y z rx ry rz"})
    return w.text()


#: Bundled variants and their file-name prefixes.
VARIANTS = {"folded": "orthoglide", "coupled": "orthoglide-coupled", "2bar": "orthoglide-2bar"}


def orthoglide_models() -> dict[str, str]:
    """File name → URDF text of the bundled Orthoglide models written with ``<vjm:leg>``
    (folded, coupled, two-bar)."""
    out = {}
    for variant, prefix in VARIANTS.items():
        for point in POINTS:
            out[f"{prefix}-{point}.urdf"] = orthoglide_urdf(point, variant)
    return out


def orthoglide_loop_models() -> dict[str, str]:
    """File name → URDF text of the bundled loop variant ``orthoglide-loop-q{0..4}.urdf``
    (parallelograms as true loops, explicit closures; ``tests/test_orthoglide_loops.py``)."""
    return {f"orthoglide-loop-{point}.urdf": orthoglide_urdf(point, "loop") for point in POINTS}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", default=str(Path(__file__).resolve().parent.parent / "models" / "urdf")
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in {**orthoglide_models(), **orthoglide_loop_models()}.items():
        (out / name).write_text(text)
        print(out / name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
