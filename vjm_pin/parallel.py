"""Parallel manipulators: several serial VJM legs from a common base meeting at one platform.

Format (documented in ``docs/parallel.md``): one URDF tree holding every leg, the ordinary VJM
role and spring tags, and in the ``urn:vjm-pin:1`` namespace::

    <vjm:platform name="platform" components="x y z rx ry rz"/>
    <vjm:leg name="leg1" frame="leg1_end" offset="0 0 0.05"/>
    <vjm:leg name="leg2" frame="leg2_end" offset="0 0 0"/>

``frame`` is the link where the leg is attached to the platform; ``offset`` (m) is the platform
reference point expressed in that link's frame (a constant rigid offset). A leg is the set of
joints on the path from the root link to its ``frame``; every joint of the robot belongs to at
least one leg, and a spring group may not be split between legs.

Each leg is turned into its own :class:`~vjm_pin.model.format.VjmModel` (a URDF of the path, plus a
fixed joint carrying the offset to a frame ``<leg>__platform`` whose orientation is world-aligned
at the reference configuration). So every leg's end frame is the same platform frame, and the
wrench transformation of the offset (``K_P = Tᵀ K_E T`` unloaded, plus the loaded geometric
term of the offset arm) is done exactly by the leg's kinematics. Then (paper §5, §6.2)::

    K_C = Σ_i K_C^(i)                       (aggregation at the common platform point)
    F   = Σ_i F^(i)(t)                      (each leg solved at the same platform location)
    t_{k+1} = t_k + K_C⁻¹ (F − F(t_k))      (eq. 11 outer loop on the aggregated stiffness)

The robot is stable for a prescribed platform location iff every leg is (eq. 23); for a
prescribed wrench it also needs ``K_C`` positive definite. Pure functions and frozen
dataclasses; no printing, no file I/O beyond reading the model.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import FrameNotFound, InputError, ModelError, NoEquilibrium, SingularStiffness
from vjm_pin.kinematics.chain import deflection as _deflection
from vjm_pin.kinematics.chain import displace
from vjm_pin.model.format import COMPONENTS, NS, VjmModel, _parse_numbers, _read_root, load_vjm
from vjm_pin.solver import EquilibriumResult, EquilibriumSolver, loaded_stiffness

_Q = f"{{{NS}}}"


@dataclass(frozen=True)
class Leg:
    """One serial leg.

    Attributes:
        name: Leg name.
        frame: Link of the robot URDF where the leg meets the platform.
        offset: (3,) platform point in ``frame`` coordinates (m).
        vm: The leg as a :class:`VjmModel` whose end frame is the platform frame.
        joints: Names of the robot joints (non-fixed) on the leg's path.
    """

    name: str
    frame: str
    offset: np.ndarray
    vm: VjmModel
    joints: tuple[str, ...]


@dataclass(frozen=True)
class ParallelModel:
    """A parallel manipulator: legs meeting at a platform.

    Attributes:
        name: Robot name.
        platform: Platform name.
        legs: The legs.
        task: Constrained platform components (indices into x y z rx ry rz).
        position: (3,) platform point at the reference configuration, world (m).
        urdf: The robot URDF text.
    """

    name: str
    platform: str
    legs: tuple[Leg, ...]
    task: tuple[int, ...]
    position: np.ndarray
    urdf: str = field(repr=False, default="")

    def leg(self, name: str) -> Leg:
        for leg in self.legs:
            if leg.name == name:
                return leg
        raise ModelError(f"unknown leg '{name}'; legs are: {[lg.name for lg in self.legs]}")


def is_parallel(source: str | Path) -> bool:
    """True when the URDF (path or text) has ``<vjm:leg>`` tags."""
    root, _, _ = _read_root(source)
    return bool(root.findall(f"{_Q}leg"))


def _leg_urdf(
    root: ET.Element, leg: str, frame: str, offset, rpy, comps: list[str]
) -> tuple[str, list[str]]:
    """URDF text of one leg (path joints + offset frame + its VJM tags) and its joint names."""
    links = {el.get("name") for el in root.findall("link")}
    if frame not in links:
        raise FrameNotFound(frame, sorted(links), f"vjm:leg '{leg}'")
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    path, link, seen = [], frame, set()
    while link in by_child:
        if link in seen:
            raise ModelError(f"leg '{leg}': kinematic loop through link '{link}'")
        seen.add(link)
        path.append(by_child[link])
        link = by_child[link].find("parent").get("link")
    path = path[::-1]
    keep_links = {link} | {j.find("child").get("link") for j in path}
    out = ET.Element("robot", {"name": f"{root.get('name', 'robot')}__{leg}"})
    for el in root.findall("link"):
        if el.get("name") in keep_links:
            out.append(copy.deepcopy(el))
    for j in path:
        out.append(copy.deepcopy(j))
    pname = f"{leg}__platform"
    ET.SubElement(out, "link", {"name": pname})
    pj = ET.SubElement(out, "joint", {"name": f"{leg}__platform_joint", "type": "fixed"})
    ET.SubElement(pj, "parent", {"link": frame})
    ET.SubElement(pj, "child", {"link": pname})
    ET.SubElement(
        pj,
        "origin",
        {
            "xyz": " ".join(repr(float(v)) for v in offset),
            "rpy": " ".join(repr(float(v)) for v in rpy),
        },
    )
    names = [j.get("name") for j in path if j.get("type") != "fixed"]
    ET.SubElement(out, f"{_Q}task", {"frame": pname, "components": " ".join(comps)})
    for el in root.findall(f"{_Q}joint"):
        if el.get("name") in names:
            out.append(copy.deepcopy(el))
    for el in root.findall(f"{_Q}spring"):
        js = (el.get("joints") or "").split()
        inside = [jn in names for jn in js]
        if all(inside) and js:
            out.append(copy.deepcopy(el))
        elif any(inside):
            raise ModelError(
                f"spring '{el.get('name')}' is split between leg '{leg}' and another part of the robot"
            )
    return ET.tostring(out, encoding="unicode"), names


def load_parallel(source: str | Path) -> ParallelModel:
    """Load a parallel VJM URDF (path or text) into per-leg :class:`VjmModel`s.

    Raises:
        ModelError: no ``<vjm:leg>``, a leg without ``frame``, duplicate leg names, a joint in
            no leg, a spring split between legs, or legs whose platform points do not coincide
            at the reference configuration.
        FrameNotFound: a leg's ``frame`` is not a link.
    """
    import pinocchio as pin

    root, text, label = _read_root(source)
    leg_els = root.findall(f"{_Q}leg")
    if not leg_els:
        raise ModelError(
            f"{label}: not a parallel model: no <vjm:leg name=... frame=... offset=.../> element"
        )
    plats = root.findall(f"{_Q}platform")
    if len(plats) > 1:
        raise ModelError(f"{label}: more than one <vjm:platform> element")
    plat = plats[0] if plats else None
    pname = (plat.get("name") if plat is not None else None) or "platform"
    comps = ((plat.get("components") if plat is not None else None) or " ".join(COMPONENTS)).split()
    bad = [c for c in comps if c not in COMPONENTS]
    if bad or not comps or len(set(comps)) != len(comps):
        raise ModelError(
            f"{label}: platform components {comps} must be distinct names from {list(COMPONENTS)}"
        )
    task = tuple(sorted(COMPONENTS.index(c) for c in comps))
    legs: list[Leg] = []
    used: set[str] = set()
    for el in leg_els:
        name = el.get("name")
        frame = el.get("frame")
        if not name or not frame:
            raise ModelError(f"{label}: <vjm:leg> needs 'name' and 'frame' attributes")
        if any(lg.name == name for lg in legs):
            raise ModelError(f"{label}: two legs named '{name}'")
        off = _parse_numbers(el.get("offset") or "0 0 0", f"leg '{name}' offset")
        if off.size != 3:
            raise ModelError(f"leg '{name}': offset needs 3 numbers (m), got {off.size}")
        # first pass: find the end orientation at the reference, then make the platform frame world-aligned
        t0, _ = _leg_urdf(root, name, frame, off, np.zeros(3), comps)
        vm0 = load_vjm(t0)
        data = vm0.model.createData()
        pin.framesForwardKinematics(vm0.model, data, vm0.reference)
        r_end = data.oMf[vm0.model.getFrameId(frame)].rotation
        rpy = pin.rpy.matrixToRpy(r_end.T)
        t1, joints = _leg_urdf(root, name, frame, off, rpy, comps)
        vm = load_vjm(t1)
        legs.append(Leg(name, frame, off, vm, tuple(joints)))
        used |= set(joints)
    all_joints = [j.get("name") for j in root.findall("joint") if j.get("type") != "fixed"]
    orphans = [j for j in all_joints if j not in used]
    if orphans:
        raise ModelError(
            f"{label}: joint(s) {orphans} belong to no leg (every joint must be on a leg's path)"
        )
    pos = []
    for lg in legs:
        s = EquilibriumSolver(lg.vm)
        pos.append(s.p0)
    scale = max(max(np.linalg.norm(p) for p in pos), 1.0)
    for lg, p in zip(legs, pos):
        if np.linalg.norm(p - pos[0]) > 1e-9 * scale:
            raise ModelError(
                f"{label}: leg '{lg.name}' puts the platform point at {np.round(p, 9).tolist()} but leg "
                f"'{legs[0].name}' at {np.round(pos[0], 9).tolist()} (reference configuration): check its offset"
            )
    return ParallelModel(root.get("name", "robot"), pname, tuple(legs), task, pos[0].copy(), text)


def transform_stiffness(k_end: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Unloaded stiffness moved by a rigid offset (wrench transformation).

    ``k_end``: (6, 6) stiffness at point E for ``(δp_E, δφ)``; ``r``: (3,) vector from E to
    the new point P, world (m). With ``δp_E = δp_P − δφ × r = δp_P + [r]× δφ``, i.e.
    ``δt_E = T δt_P`` with ``T = [[I, [r]×], [0, I]]``, the stiffness at P is ``Tᵀ K_E T``.
    Only valid unloaded: a load adds the geometric term of the offset arm, which the leg
    models of :func:`load_parallel` include exactly.
    """
    r = np.asarray(r, float)
    rx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    t = np.eye(6)
    t[:3, 3:] = rx
    return t.T @ np.asarray(k_end, float) @ t


@dataclass(frozen=True)
class LegResult:
    """One leg at a robot equilibrium.

    Attributes:
        name: Leg name.
        equilibrium: The leg's :class:`EquilibriumResult` (its ``wrench`` is the force (N) and
            moment (N·m) the leg carries at the platform point, world axes).
    """

    name: str
    equilibrium: EquilibriumResult

    @property
    def wrench(self) -> np.ndarray:
        return self.equilibrium.wrench

    @property
    def stable(self) -> bool | None:
        return self.equilibrium.stable


@dataclass(frozen=True)
class RobotEquilibrium:
    """A loaded equilibrium of the whole robot.

    Attributes:
        deflection: (6,) platform displacement from the reference (m, world rotation vector rad).
        position: (3,) platform point (m). rotation: (3, 3) platform orientation.
        wrench: (6,) external wrench on the platform = Σ leg wrenches (N, N·m about the platform point).
        legs: Per-leg results, model order.
        converged: All legs converged (and, wrench-driven, the wrench error is within tolerance).
        path: How it was found (``"displacement"`` or ``"eq11(k)"``).
    """

    deflection: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    wrench: np.ndarray
    legs: tuple[LegResult, ...]
    converged: bool
    path: str = "displacement"

    @property
    def unstable_legs(self) -> list[str]:
        """Names of the legs whose equilibrium is unstable (eq. 23)."""
        return [lg.name for lg in self.legs if lg.stable is False]

    @property
    def stable(self) -> bool:
        """Stable for a prescribed platform location iff every leg is stable."""
        return all(lg.stable for lg in self.legs)

    def to_dict(self) -> dict:
        """JSON-ready summary with per-leg results (``legs``: name, wrench, stable)."""
        return {
            "deflection": self.deflection.tolist(),
            "wrench": self.wrench.tolist(),
            "stable": self.stable,
            "unstable_legs": self.unstable_legs,
            "converged": self.converged,
            "legs": [
                {"name": lg.name, "wrench": lg.wrench.tolist(), "stable": lg.stable}
                for lg in self.legs
            ],
        }


class RobotSolver:
    """Equilibrium, stiffness and stability of a :class:`ParallelModel`.

    Keeps one :class:`EquilibriumSolver` per leg (solver options are passed through).
    """

    def __init__(self, pm: ParallelModel, **solver_options):
        self.pm = pm
        self.solvers = tuple(EquilibriumSolver(lg.vm, **solver_options) for lg in pm.legs)
        s0 = self.solvers[0]
        self.p0, self.r0 = s0.p0, s0.r0
        self.task = list(pm.task)

    def _check_guess(self, x0):
        if x0 is None:
            return [None] * len(self.solvers)
        if isinstance(x0, RobotEquilibrium):
            return [lg.equilibrium.x for lg in x0.legs]
        x0 = list(x0)
        if len(x0) != len(self.solvers):
            raise InputError(
                f"x0 needs one configuration per leg ({len(self.solvers)}), got {len(x0)}"
            )
        return x0

    def solve(
        self, deflection=None, *, target=None, x0=None, fast_fail: bool = False
    ) -> RobotEquilibrium:
        """Robot equilibrium for a prescribed platform location: every leg is solved at the
        same platform pose (eq. 5 per leg) and the leg wrenches are summed.

        Args:
            deflection: (6,) or (3,) platform displacement (m, world rotation vector rad), or
            target: (position (3,), rotation (3, 3)) of the platform.
            x0: warm start: a previous :class:`RobotEquilibrium` or one configuration per leg.
            fast_fail: one Newton attempt per leg, no continuation or restarts (trial points
                of a line search; see :meth:`EquilibriumSolver.solve`).
        Raises:
            NoEquilibrium: a leg has no equilibrium there (the message names the leg).
        """
        if (deflection is None) == (target is None):
            raise InputError("give exactly one of a deflection or a target pose")
        if deflection is not None:
            d = np.asarray(deflection, float).ravel()
            if d.size == 3:
                d = np.concatenate([d, np.zeros(3)])
            if d.size != 6 or not np.all(np.isfinite(d)):
                raise InputError(
                    f"platform deflection must be 3 or 6 finite numbers (m, rad), got {d.tolist()}"
                )
            target = displace(self.p0, self.r0, d)
        guesses = self._check_guess(x0)
        legs = []
        for lg, s, g in zip(self.pm.legs, self.solvers, guesses):
            try:
                r = s.solve(target=target, x0=g, fast_fail=fast_fail)
            except NoEquilibrium as e:
                raise NoEquilibrium(f"leg '{lg.name}': {e}", e.result, e.residual) from None
            legs.append(LegResult(lg.name, r))
        p, rot = legs[0].equilibrium.position, legs[0].equilibrium.rotation
        w = np.sum([lg.wrench for lg in legs], axis=0)
        return RobotEquilibrium(
            _deflection(self.p0, self.r0, p, rot),
            p.copy(),
            rot.copy(),
            w,
            tuple(legs),
            all(lg.equilibrium.converged for lg in legs),
        )

    def stiffness(self, eq: RobotEquilibrium | None = None, method: str = "eq30") -> np.ndarray:
        """Loaded Cartesian stiffness of the robot at the platform point, ``K_C = Σ K_C^(i)``
        (§5; eq. 30/32/33 per leg), (6, 6) in N/m, N/rad, N·m/rad, world axes. ``eq=None``:
        unloaded reference."""
        if eq is None:
            eq = self.solve(np.zeros(6))
        return np.sum(
            [
                loaded_stiffness(lg.vm, r.equilibrium, method, s.kin).stiffness
                for lg, r, s in zip(self.pm.legs, eq.legs, self.solvers)
            ],
            axis=0,
        )

    def leg_stiffnesses(self, eq: RobotEquilibrium, method: str = "eq30") -> dict:
        """Per-leg K_C^(i) (6, 6) at the platform point, by leg name."""
        return {
            lg.name: loaded_stiffness(lg.vm, r.equilibrium, method, s.kin).stiffness
            for lg, r, s in zip(self.pm.legs, eq.legs, self.solvers)
        }

    def solve_wrench(
        self, wrench, *, x0=None, max_outer: int = 50, tol: float = 1e-9
    ) -> RobotEquilibrium:
        """Robot equilibrium for a prescribed external wrench on the platform (eq. 11):
        ``t_{k+1} = t_k + K_C⁻¹(F − Σ F^(i)(t_k))`` with step halving, ``K_C`` aggregated.

        Raises:
            SingularStiffness: the aggregated stiffness is singular (a free platform motion).
            NoEquilibrium: no convergence (e.g. the load exceeds the critical force).
        """
        w = np.asarray(wrench, float).ravel()
        if w.size == 3:
            w = np.concatenate([w, np.zeros(3)])
        if w.size != 6 or not np.all(np.isfinite(w)):
            raise InputError(
                f"wrench must be 3 or 6 finite numbers (N, N·m), got {np.asarray(wrench).tolist()}"
            )
        free = [i for i in range(6) if i not in self.task]
        if np.any(w[free] != 0):
            raise InputError(
                f"wrench components {[COMPONENTS[i] for i in free if w[i]]} are not constrained by the platform"
            )
        res = self.solve(np.zeros(6), x0=x0)
        fscale = max(float(np.abs(w).max()), 1e-300)
        for outer in range(max_outer):
            err = (w - res.wrench)[self.task]
            if np.abs(err).max() <= tol * fscale:
                return replace(res, path=f"eq11({outer})")
            k = self.stiffness(res)[np.ix_(self.task, self.task)]
            ev = np.linalg.eigvals(0.5 * (k + k.T)).real
            if np.abs(ev).min() <= 1e-12 * np.abs(ev).max():
                raise SingularStiffness(
                    f"wrench-driven robot equilibrium (eq. 11): the aggregated stiffness is singular "
                    f"(eigenvalues {np.sort(ev).tolist()})",
                    ev,
                )
            dt_task = np.linalg.solve(k, err)
            step, new = 1.0, None
            for _ in range(30):
                dt = np.zeros(6)
                dt[self.task] = step * dt_task
                try:
                    cand = self.solve(target=displace(res.position, res.rotation, dt), x0=res)
                    if np.abs((w - cand.wrench)[self.task]).max() < np.abs(err).max():
                        new = cand
                        break
                except NoEquilibrium:
                    pass
                step *= 0.5
            if new is None:
                break
            res = new
        raise NoEquilibrium(
            f"wrench-driven robot equilibrium (eq. 11) did not converge: wrench error "
            f"{np.abs((w - res.wrench)[self.task]).max():.3g} N",
            None,
            float(np.abs((w - res.wrench)[self.task]).max()),
        )


@dataclass(frozen=True)
class RobotCurvePoint:
    """One point of a robot force–deflection curve.

    Attributes:
        s: Displacement along the direction (m, or rad for a rotational direction).
        force: Wrench component along the direction (N or N·m): ``d·F``.
        stiffness: Directional stiffness ``dᵀ K_C d`` (N/m).
        stable: Every leg stable. unstable_legs: names of the unstable legs.
        equilibrium: The :class:`RobotEquilibrium`.
    """

    s: float
    force: float
    stiffness: float
    stable: bool
    unstable_legs: tuple[str, ...]
    equilibrium: RobotEquilibrium = field(repr=False)

    @property
    def deflection(self) -> float:
        """Alias of ``s`` (the name :class:`vjm_pin.analysis.curve.CurvePoint` uses)."""
        return self.s

    @property
    def wrench(self) -> np.ndarray:
        """(6,) external wrench on the platform (N, N·m)."""
        return self.equilibrium.wrench


def trace_robot_curve(
    pm_or_solver, direction, max_deflection: float, n_points: int = 50, method: str = "eq30"
) -> list[RobotCurvePoint]:
    """Force–deflection curve of the robot for platform displacements ``s·d`` (0 ≤ s ≤ max),
    displacement-driven (so it passes buckling), each point warm-started from the previous
    one, with the aggregated stiffness and leg stability at every point.

    Args:
        direction: (6,) or (3,) direction (normalised here).
        max_deflection: largest ``s`` (m).
    """
    rs = pm_or_solver if isinstance(pm_or_solver, RobotSolver) else RobotSolver(pm_or_solver)
    d = np.asarray(direction, float).ravel()
    if d.size == 3:
        d = np.concatenate([d, np.zeros(3)])
    if d.size != 6 or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
        raise InputError(
            f"direction must be 3 or 6 finite numbers, not all zero, got {np.asarray(direction).tolist()}"
        )
    if not (np.isfinite(max_deflection) and max_deflection > 0) or n_points < 2:
        raise InputError("max_deflection must be positive and n_points ≥ 2")
    d = d / np.linalg.norm(d)
    out: list[RobotCurvePoint] = []
    prev = None
    for s in np.linspace(0.0, max_deflection, n_points):
        eq = rs.solve(s * d, x0=prev)
        k = rs.stiffness(eq, method)
        out.append(
            RobotCurvePoint(
                float(s),
                float(d @ eq.wrench),
                float(d @ k @ d),
                eq.stable,
                tuple(eq.unstable_legs),
                eq,
            )
        )
        prev = eq
    return out


# --------------------------------------------------------------------------------------------
# Force–deflection curves with the platform free across the loading direction (Table 2, Fig. 7)
# --------------------------------------------------------------------------------------------

#: A step whose directional stiffness falls below this fraction of the previous one is a
#: critical point (the older rule of the serial tracer; parallel curves keep it until the mechanism core replaces this module).
ROBOT_DROP_RATIO = 0.5
#: Amplitudes (m or rad) of the perturbation along the unstable mode that leaves a saddle.
_PERTURB = (1e-4, 1e-3, 1e-2)


@dataclass(frozen=True)
class RobotCriticalPoint:
    """A critical (buckling) point of a robot force–deflection curve.

    Attributes:
        force: Critical force along the direction (N).
        deflection: Critical deflection along the direction (m).
        stiffness_before: Directional stiffness (N/m) at the end of the pre-critical branch.
        stiffness_after: Directional stiffness (N/m) of the followed branch just after.
        index: Index in ``RobotCurve.points`` of the first point after it.
        kind: ``"platform"`` (the free platform coordinates lose stability: the reduced
            matrix ``Bᵀ K_C B`` gets a negative eigenvalue, located by regula falsi) or
            ``"drop"`` (a stiffness drop without that, e.g. a leg snapping to another
            configuration; located by bisection).
        mode: (6,) the unstable platform mode (``B v``), world axes, for ``kind="platform"``.
    """

    force: float
    deflection: float
    stiffness_before: float
    stiffness_after: float
    index: int
    kind: str
    mode: np.ndarray | None = field(default=None, repr=False)


@dataclass(frozen=True)
class RobotCurve:
    """A robot force–deflection curve.

    Attributes:
        direction: (6,) unit direction (translation), world axes.
        free: Whether the platform was free across the direction (zero wrench there).
        points: The followed (stable when one exists) branch.
        critical: Critical points found on it.
        stopped: Why the curve ends before ``max_deflection`` (no equilibrium found), or "".
    """

    direction: np.ndarray
    free: bool
    points: tuple[RobotCurvePoint, ...]
    critical: tuple[RobotCriticalPoint, ...]
    branches: tuple = ()  # no unstable-branch tracing for robots (kept for the plot helpers)
    stopped: str = ""  # why the curve ends before max_deflection ("" when it does not)

    @property
    def deflections(self) -> np.ndarray:
        return np.array([p.s for p in self.points])

    @property
    def forces(self) -> np.ndarray:
        return np.array([p.force for p in self.points])


def _complement(d: np.ndarray, task: list[int]) -> np.ndarray:
    """Orthonormal basis (6, k) of the task components orthogonal to ``d``."""
    e = np.eye(6)[:, task]
    u, s, _ = np.linalg.svd(e - np.outer(d, d @ e), full_matrices=False)
    return u[:, s > 1e-9]


def directional_stiffness(k: np.ndarray, d: np.ndarray, b: np.ndarray | None) -> float:
    """Stiffness along ``d`` (N/m): ``dᵀ K d`` with the platform held (``b`` None), or the
    Schur complement ``dᵀKd − dᵀKB (BᵀKB)⁻¹ BᵀKd`` with the platform free along the columns
    of ``b`` (the reciprocal of ``dᵀ K⁻¹ d`` when ``[d B]`` spans all components)."""
    kdd = float(d @ k @ d)
    if b is None or b.shape[1] == 0:
        return kdd
    kbb = b.T @ k @ b
    kbd = b.T @ k @ d
    kdb = d @ k @ b
    try:
        return kdd - float(kdb @ np.linalg.solve(kbb, kbd))
    except np.linalg.LinAlgError:
        return float("nan")


def _energy(eq: RobotEquilibrium) -> float:
    return float(sum(lg.equilibrium.energy for lg in eq.legs))


def _free_eigen(rs: RobotSolver, eq: RobotEquilibrium, b: np.ndarray):
    k = rs.stiffness(eq)
    h = b.T @ k @ b
    lam, v = np.linalg.eigh(0.5 * (h + h.T))
    return k, lam, v


def solve_free(
    rs: RobotSolver,
    d: np.ndarray,
    s: float,
    start: RobotEquilibrium,
    *,
    leave_saddle: bool = True,
    tol: float = 1e-9,
    max_iter: int = 60,
):
    """Robot equilibrium with the platform displaced by ``s`` along the translation ``d`` and
    free across it: ``Bᵀ F = 0`` for the complement basis ``B`` (no external load there).

    The free coordinates minimise the spring energy Σ Π⁽ⁱ⁾ (each leg's eq. 5 equilibrium is a
    constrained energy minimum, so ``∂Π/∂t = F``): saddle-free Newton steps
    ``δy = −|BᵀK_C B|⁻¹ Bᵀ F`` (eigenvalues by their modulus) with an energy line search, so
    a step never climbs towards a saddle. With ``leave_saddle`` an equilibrium where
    ``BᵀK_C B`` is indefinite (the symmetric branch past a bifurcation) is left along its
    unstable mode, both signs, and the lower-energy stable result is kept.

    Returns:
        (eq, k, lam): the equilibrium, its ``K_C`` (6, 6) and the eigenvalues of ``BᵀK_C B``.
    Raises:
        NoEquilibrium: a leg has no equilibrium, or Newton does not converge.
    """
    b = _complement(d, rs.task)
    # move along d from the start's pose to s (exact for a translation)
    s0 = float(d @ start.deflection)
    eq = rs.solve(target=displace(start.position, start.rotation, (s - s0) * d), x0=start)

    def newton(eq, patience=None):
        fscale = max(float(np.linalg.norm(eq.wrench)), 1.0)
        history = []
        for _ in range(max_iter):
            k, lam, v = _free_eigen(rs, eq, b)
            g = b.T @ eq.wrench
            if np.linalg.norm(g) <= tol * fscale:
                return eq, k, lam, v
            history.append(np.linalg.norm(g))
            if patience and len(history) > patience and history[-1] > 0.5 * history[-1 - patience]:
                break  # crawling (a flat saddle region): give up this start
            if leave_saddle:  # saddle-free Newton: descend the energy
                mod = np.maximum(np.abs(lam), 1e-10 * np.abs(lam).max())
            else:  # plain Newton: continue the branch, stable or not
                mod = np.where(
                    np.abs(lam) > 1e-10 * np.abs(lam).max(), lam, 1e-10 * np.abs(lam).max()
                )
            dy = -(v @ ((v.T @ g) / mod))
            e0, g0 = _energy(eq), np.linalg.norm(g)
            step, new = 1.0, None
            for _ in range(30):
                try:
                    cand = rs.solve(
                        target=displace(eq.position, eq.rotation, b @ (step * dy)),
                        x0=eq,
                        fast_fail=True,
                    )
                except NoEquilibrium:
                    cand = None
                if cand is not None:
                    e1 = _energy(cand)
                    g1 = np.linalg.norm(b.T @ cand.wrench)
                    descends = e1 < e0 - 1e-14 * abs(e0) or (e1 <= e0 + 1e-12 * abs(e0) and g1 < g0)
                    if descends if leave_saddle else g1 < g0:
                        new = cand
                        break
                step *= 0.5
            if new is None:
                return eq, k, lam, v
            eq = new
        k, lam, v = _free_eigen(rs, eq, b)
        return eq, k, lam, v

    eq, k, lam, v = newton(eq, patience=20)
    fscale = max(float(np.linalg.norm(eq.wrench)), 1.0)
    converged = np.linalg.norm(b.T @ eq.wrench) <= 1e-6 * fscale
    if leave_saddle and converged and lam.size and lam.min() < 0:
        best = None
        for amp in _PERTURB:
            for sign in (1.0, -1.0):
                try:
                    start2 = rs.solve(
                        target=displace(eq.position, eq.rotation, sign * amp * (b @ v[:, 0])),
                        x0=eq,
                        fast_fail=True,
                    )
                    e2, k2, lam2, v2 = newton(start2, patience=10)
                except NoEquilibrium:
                    continue
                ok = np.linalg.norm(b.T @ e2.wrench) <= 1e-6 * fscale and lam2.min() > 0
                if ok and (best is None or _energy(e2) < _energy(best[0])):
                    best = (e2, k2, lam2, v2)
            if best is not None:
                break
        if best is not None:
            eq, k, lam, v = best
    if not np.linalg.norm(b.T @ eq.wrench) <= 1e-6 * fscale:
        raise NoEquilibrium(
            f"free-platform robot equilibrium at s = {s:.6g}: wrench across the direction "
            f"{np.linalg.norm(b.T @ eq.wrench):.3g} did not vanish",
            None,
            float(np.linalg.norm(b.T @ eq.wrench)),
        )
    return eq, k, lam


def _robot_point(s, d, b, eq, k, lam) -> RobotCurvePoint:
    stable_free = bool(lam.size == 0 or lam.min() > 0)
    unstable = tuple(eq.unstable_legs) + (() if stable_free else ("platform",))
    return RobotCurvePoint(
        float(s),
        float(d @ eq.wrench),
        directional_stiffness(k, d, b),
        bool(eq.stable and stable_free),
        unstable,
        eq,
    )


def trace_robot_force_curve(
    pm_or_solver,
    direction,
    max_deflection: float,
    steps: int = 40,
    *,
    free: bool = True,
    refine_tol: float = 1e-4,
    progress=None,
) -> RobotCurve:
    """Force–deflection curve of a parallel robot with critical-point detection (paper §6.2,
    Fig. 7, Table 2).

    The platform is displaced by ``s·d`` (``d`` a translation, ``0 ≤ s ≤ max_deflection``);
    with ``free`` (default) the other platform components carry no load (:func:`solve_free`),
    which is the loading of Table 2 (a force along the bisector at the platform point);
    without, the platform is held (``solve(s·d)``, as :func:`trace_robot_curve`).
    Stability: every leg stable (eq. 23) and, free, ``BᵀK_C B`` positive definite.

    Critical points (rule of :mod:`vjm_pin.analysis.curve`): between a stable point ``a`` and
    the next ``b``, when ``b`` is unstable, was reached by leaving a saddle, or its stiffness
    is below :data:`ROBOT_DROP_RATIO` × ``a``'s. If the branch continued from ``a`` without
    leaving saddles loses the positive definiteness of ``BᵀK_C B`` before ``b``, the root of
    its smallest eigenvalue is found by Illinois regula falsi (``kind="platform"``);
    otherwise the drop is bracketed by bisection (``kind="drop"``) until the force is known
    to ``refine_tol``.
    """
    rs = pm_or_solver if isinstance(pm_or_solver, RobotSolver) else RobotSolver(pm_or_solver)
    d = np.asarray(direction, float).ravel()
    if d.size == 3:
        d = np.concatenate([d, np.zeros(3)])
    if d.size != 6 or not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0 or np.any(d[3:]):
        raise InputError(
            f"direction must be a translation (3 numbers, or 6 with zero rotation), not all zero, "
            f"got {np.asarray(direction).tolist()}"
        )
    if not (np.isfinite(max_deflection) and max_deflection > 0):
        raise InputError(f"max_deflection must be a positive number (m), got {max_deflection}")
    if int(steps) != steps or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps}")
    d = d / np.linalg.norm(d)
    missing = [COMPONENTS[i] for i in range(3) if d[i] and i not in rs.task]
    if missing:
        raise InputError(f"direction has components {missing} the platform does not constrain")
    b = _complement(d, rs.task) if free else None

    def at(s, start, leave=True):
        if free:
            eq, k, lam = solve_free(rs, d, s, start, leave_saddle=leave)
        else:
            eq = rs.solve(s * d, x0=start)
            k, lam = rs.stiffness(eq), np.zeros(0)
        return _robot_point(s, d, b, eq, k, lam), lam

    s_grid = [max_deflection * i / steps for i in range(steps + 1)]
    zero = rs.solve(np.zeros(6))
    points: list[RobotCurvePoint] = []
    critical: list[RobotCriticalPoint] = []
    prev_eq = zero
    stopped = ""
    for i, s in enumerate(s_grid):
        try:
            p, _ = at(s, prev_eq)
        except NoEquilibrium as e:
            stopped = f"no equilibrium at s = {s:.6g} m: {e}"
            break
        if points:
            a = points[-1]
            drop = (
                a.stiffness > 0
                and np.isfinite(a.stiffness)
                and np.isfinite(p.stiffness)
                and p.stiffness < ROBOT_DROP_RATIO * a.stiffness
            )
            if a.stable and (not p.stable or drop):
                c = _refine_robot(at, rs, d, b, a, p, i, refine_tol)
                h = max_deflection / steps
                if not critical or abs(c.deflection - critical[-1].deflection) > 1e-3 * h:
                    critical.append(c)  # else the same transition, seen again one step later
        points.append(p)
        prev_eq = p.equilibrium
        if progress is not None:
            progress(i + 1, steps + 1)
    return RobotCurve(d, bool(free), tuple(points), tuple(critical), stopped=stopped)


def _min_lam(at, s, start):
    p, lam = at(s, start, leave=False)
    return p, (float(lam.min()) if lam.size else np.inf)


def _refine_robot(at, rs, d, b, a: RobotCurvePoint, bpt: RobotCurvePoint, index, refine_tol):
    """Locate the critical point between ``a`` (stable) and ``bpt`` (see
    :func:`trace_robot_force_curve`)."""
    from vjm_pin.analysis.curve import MAX_BISECTIONS, illinois

    lo, flo = _min_lam(at, a.s, a.equilibrium)
    hi, fhi = None, None
    if b is not None:
        try:
            hi, fhi = _min_lam(at, bpt.s, a.equilibrium)
        except NoEquilibrium:
            hi = None
    if hi is not None and flo > 0 and fhi < 0:
        def evaluate(s, _lo, _hi):
            try:  # always from a's state: the continued branch, not a neighbour near the root
                m, fm = _min_lam(at, s, a.equilibrium)
            except NoEquilibrium:
                return None
            return m, -fm  # illinois wants f < 0 on the stable side

        lo, flo, hi, fhi, _, _ = illinois(
            evaluate, lo, -flo, hi, -fhi, lambda p: p.s,
            lambda lo_, hi_, m, s: abs(hi_.s - lo_.s) <= refine_tol * abs(s), MAX_BISECTIONS,
        )
        w = flo / (flo - fhi)
        s_c = lo.s + w * (hi.s - lo.s)
        # the force at the root: the pre-critical branch extrapolated from lo with a's tangent
        # stiffness (on the continued branch the free coordinates diverge at the root, so a
        # solve there is ill-conditioned)
        f_c = lo.force + a.stiffness * (s_c - lo.s)
        kbb = b.T @ rs.stiffness(lo.equilibrium) @ b
        _, vec = np.linalg.eigh(0.5 * (kbb + kbb.T))
        # stiffness before: the last stable grid point (on the symmetric branch the directional
        # stiffness diverges at the root when the mode couples to d)
        return RobotCriticalPoint(
            float(f_c),
            float(s_c),
            float(a.stiffness),
            float(bpt.stiffness),
            index,
            "platform",
            b @ vec[:, 0],
        )
    # bisection on "still on the pre-critical branch"
    lo_p, hi_p = a, bpt
    for _ in range(MAX_BISECTIONS):
        ds = hi_p.s - lo_p.s
        if abs(lo_p.stiffness * ds) <= refine_tol * max(abs(lo_p.force), abs(hi_p.force), 1e-300):
            break
        s = 0.5 * (lo_p.s + hi_p.s)
        try:
            m, _ = at(s, a.equilibrium)
        except NoEquilibrium:
            break
        if m.stable and m.stiffness >= ROBOT_DROP_RATIO * a.stiffness:
            lo_p = m
        else:
            hi_p = m
    return RobotCriticalPoint(
        float(lo_p.force),
        float(lo_p.s),
        float(lo_p.stiffness),
        float(bpt.stiffness),
        index,
        "drop",
    )
