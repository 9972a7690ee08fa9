"""Frozen copy of ``vjm_pin/loads.py`` (``solve_loaded``, the gravity/payload Newton path of
open chains) as released before issue 13 deleted it: the "before" side of
``scripts/benchmark.py``'s map section. Not part of the package; never edit it."""


from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from vjm_pin.exceptions import InputError, LoadError, NoEquilibrium
from vjm_pin.kinematics.chain import Kinematics, deflection
from vjm_pin.model.format import VjmModel

#: Standard gravity (m/s²), ISO 80000-3.
STANDARD_GRAVITY = 9.80665


@dataclass(frozen=True)
class LinkLoads:
    """Dead loads on the links.

    Attributes:
        gravity: (3,) gravity acceleration, world axes (m/s²); zeros for none. Each body of
            the Pinocchio model carries its weight at its centre of mass (URDF inertials;
            links on fixed joints are merged into their parent body).
    """

    gravity: np.ndarray

    def __post_init__(self):
        g = np.asarray(self.gravity, float).reshape(-1)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise InputError(
                f"gravity must be 3 finite numbers (m/s²), got {np.asarray(self.gravity).tolist()}"
            )
        object.__setattr__(self, "gravity", g)

    @classmethod
    def earth(cls) -> LinkLoads:
        return cls(np.array([0.0, 0.0, -STANDARD_GRAVITY]))

    @classmethod
    def none(cls) -> LinkLoads:
        return cls(np.zeros(3))


def payload_wrench(mass_kg: float, g: float = STANDARD_GRAVITY) -> np.ndarray:
    """End wrench (6,) of a payload of ``mass_kg`` at the end frame origin: (0, 0, −m g, 0, 0, 0) N."""
    m = float(mass_kg)
    if not np.isfinite(m) or m < 0:
        raise LoadError(f"payload mass must be a finite non-negative number of kg, got {mass_kg}")
    return np.array([0.0, 0.0, -m * g, 0.0, 0.0, 0.0])


def _model_with_gravity(model, gravity: np.ndarray):
    m = model.copy()  # never change the caller's model
    m.gravity.linear = np.asarray(gravity, float)
    return m


def total_mass(vm: VjmModel) -> float:
    """Sum of the body masses of the model (kg)."""
    return float(sum(i.mass for i in vm.model.inertias))


def generalized_load(vm: VjmModel, loads: LinkLoads, x: np.ndarray) -> np.ndarray:
    """``G(x) = Σ J_iᵀ f_i`` (n,) (N·m, N): the generalised force of the link loads (eq. 5')."""
    m = _model_with_gravity(vm.model, loads.gravity)
    d = m.createData()
    return -np.asarray(pin.computeGeneralizedGravity(m, d, np.asarray(x, float))).copy()


def load_hessian(vm: VjmModel, loads: LinkLoads, x: np.ndarray) -> np.ndarray:
    """``H^G = ∂G/∂x`` (n, n): the extra Hessian term of eq. (28') from the link loads."""
    m = _model_with_gravity(vm.model, loads.gravity)
    d = m.createData()
    dg = pin.computeGeneralizedGravityDerivatives(m, d, np.asarray(x, float))
    return -np.asarray(dg).copy()


def potential_energy(vm: VjmModel, loads: LinkLoads, x: np.ndarray) -> float:
    """Potential ``V(x)`` of the link loads (J), with ``G = −∂V/∂x``."""
    m = _model_with_gravity(vm.model, loads.gravity)
    d = m.createData()
    return float(pin.computePotentialEnergy(m, d, np.asarray(x, float)))


def loaded_blocks(vm: VjmModel, x, wrench, loads: LinkLoads, kin: Kinematics | None = None):
    """:class:`~vjm_pin.solver.Blocks` at ``x`` under the end ``wrench`` with ``H + H^G``
    (eq. 28'): feed it to ``stiffness_from_blocks`` and ``check_stability``."""
    from vjm_pin.solver import blocks_at

    b = blocks_at(vm, x, wrench, kin)
    if not np.any(loads.gravity):  # H^G = 0 without link loads
        return b
    hg = load_hessian(vm, loads, x)
    ti, qi = vm.theta_idx, vm.q_idx
    return replace(
        b,
        H_tt=b.H_tt + hg[np.ix_(ti, ti)],
        H_tq=b.H_tq + hg[np.ix_(ti, qi)],
        H_qt=b.H_qt + hg[np.ix_(qi, ti)],
        H_qq=b.H_qq + hg[np.ix_(qi, qi)],
    )


@dataclass(frozen=True)
class LoadedEquilibrium:
    """Equilibrium of eq. (5') for a given end wrench and link loads.

    Attributes:
        x: (n,) configuration (m, rad). theta: (nθ,) spring coordinates.
        wrench: (6,) end wrench (N, N·m, world axes; payload included).
        deflection: (6,) end displacement from the unloaded reference (m, world rotation vector rad).
        position: (3,) end position (m). rotation: (3, 3).
        iterations: Newton iterations. residual: max |eq. 5' residual| (N·m, N).
        stiffness: :class:`~vjm_pin.solver.StiffnessResult` of eq. (30) with ``H + H^G``, or
            None if singular. stability: :class:`~vjm_pin.solver.StabilityResult` (eq. 23).
    """

    x: np.ndarray
    theta: np.ndarray
    wrench: np.ndarray
    deflection: np.ndarray
    position: np.ndarray
    rotation: np.ndarray
    iterations: int
    residual: float
    stiffness: object = None
    stability: object = None

    @property
    def stable(self):
        return None if self.stability is None else self.stability.stable


def static_residual(
    vm: VjmModel, loads: LinkLoads, x, wrench, kin: Kinematics | None = None
) -> np.ndarray:
    """Residual of eq. (5') over all coordinates (n,): ``K(θ−θ₀) − Jᵀ F − G`` on the spring
    coordinates and ``−J_qᵀ F − G_q`` on the passive ones (locked joints excluded)."""
    kin = kin or Kinematics(vm.model, vm.frame_id)
    st = kin.evaluate(np.asarray(x, float), hessian=False)
    gen = st.jacobian.T @ np.asarray(wrench, float)
    if np.any(loads.gravity):  # no model copy and pin.Data without link loads (G = 0)
        gen = gen + generalized_load(vm, loads, x)
    r = -gen
    r[vm.theta_idx] += vm.K_theta @ (np.asarray(x)[vm.theta_idx] - vm.theta0)
    idx = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    return r[idx]


def solve_loaded(
    vm: VjmModel,
    wrench=None,
    loads: LinkLoads | None = None,
    *,
    tol: float = 1e-10,
    max_iter: int = 50,
    steps: int = 1,
    method: str = "eq30",
    kin: Kinematics | None = None,
) -> LoadedEquilibrium:
    """Equilibrium under an end wrench and link loads (eq. 5'), with its loaded stiffness
    (eq. 28'/30) and stability (eq. 23 with ``H + H^G``).

    Newton on ``r(θ) = K_θ(θ−θ₀) − J_θᵀF − G_θ(x) = 0`` with the Jacobian ``K_θ − H_θθ − H^G_θθ``,
    from the unloaded reference, with load continuation over ``steps`` equal increments
    (and automatic halving when an increment fails).

    Raises:
        LoadError: the model has perfect passive joints.
        InputError: a wrench with components outside the task.
        NoEquilibrium: Newton did not converge (e.g. the load exceeds a buckling load).
    """
    from vjm_pin.exceptions import SingularStiffness
    from vjm_pin.solver import check_stability, stiffness_from_blocks

    if vm.n_q:
        raise LoadError(
            f"model '{vm.name}' has passive joints {vm.q_names}: link loads need a prescribed deflection; "
            "the wrench-driven solve with gravity supports spring and actuated joints only"
        )
    loads = loads or LinkLoads.none()
    w = np.zeros(6) if wrench is None else np.asarray(wrench, float).reshape(-1)
    if w.size == 3:
        w = np.concatenate([w, np.zeros(3)])
    if w.shape != (6,) or not np.all(np.isfinite(w)):
        raise InputError(
            f"wrench must be 3 or 6 finite numbers (N, N·m), got {np.asarray(wrench).tolist()}"
        )
    free = [i for i in range(6) if i not in vm.task]
    if np.any(w[free] != 0):
        raise InputError(f"wrench acts on components outside the task {vm.task_names}")
    kin = kin or Kinematics(vm.model, vm.frame_id)  # a map worker passes its own (one pin.Data)
    p0, r0 = kin.placement(vm.reference)
    ti = vm.theta_idx
    scale = max(float(np.abs(vm.K_theta).max()), 1e-300)
    x = vm.reference.copy()
    total = 0
    alpha = 0.0
    step = 1.0 / max(int(steps), 1)
    res_norm = 0.0
    while alpha < 1.0:
        a_next = min(1.0, alpha + step)
        loads_a = LinkLoads(a_next * loads.gravity)
        xk = x.copy()
        ok = False
        for it in range(max_iter):
            r = static_residual(vm, loads_a, xk, a_next * w, kin)
            res_norm = float(np.abs(r).max()) if r.size else 0.0
            tau = vm.K_theta @ (xk[ti] - vm.theta0)
            if res_norm <= tol * max(
                float(np.abs(tau).max()) if tau.size else 0.0, 1e-6 * scale, 1e-12
            ):
                ok = True
                break
            b = loaded_blocks(vm, xk, a_next * w, loads_a, kin)
            jac = vm.K_theta - b.H_tt
            try:
                dx = np.linalg.solve(jac, -r)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(dx)):
                break
            big = float(np.abs(dx).max())
            if big > 0.3:  # rad or m: damp far steps
                dx *= 0.3 / big
            xk[ti] += dx
            total += 1
        if ok:
            x, alpha = xk, a_next
        else:
            step *= 0.5
            if step < 1e-4:
                raise NoEquilibrium(
                    f"no equilibrium under the wrench {w.tolist()} and link loads (gravity {loads.gravity.tolist()} m/s²) "
                    f"after {total} Newton iterations: the load may exceed the buckling load (residual {res_norm:.3g})",
                    None,
                    res_norm,
                )
    st = kin.evaluate(x, hessian=False)
    b = loaded_blocks(vm, x, w, loads, kin)
    try:
        k = stiffness_from_blocks(b, vm.task, method)
    except SingularStiffness:
        k = None
    return LoadedEquilibrium(
        x=x,
        theta=x[ti].copy(),
        wrench=w,
        deflection=deflection(p0, r0, st.position, st.rotation),
        position=st.position.copy(),
        rotation=st.rotation.copy(),
        iterations=total,
        residual=res_norm,
        stiffness=k,
        stability=check_stability(b),
    )
