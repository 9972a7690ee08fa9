"""Stiffness indices of the end frame derived from the loaded Cartesian stiffness K_C (eq. 30).

Weakest translational stiffness (:func:`weakest_translation`). A force ``s û`` (N, unit
world direction ``û``) on the end, with the end *free in every other task component* (no
other force, no moment), displaces it by ``δt = C [s û; 0]`` with the compliance
``C = K_C⁻¹`` on the task rows; the displacement along the force is ``s ûᵀ C_tt û``
(``C_tt``: the translational block of ``C``). The directional stiffness is therefore

    k(û) = 1 / (ûᵀ C_tt û) = 1 / (ûᵀ sym(C_tt) û),    sym(A) = ½(A + Aᵀ),

and the weakest direction is the eigenvector of the largest eigenvalue of ``sym(C_tt)``:
``k_min = 1 / λ_max(sym C_tt)`` (N/m). This is the stiffness a force really meets. The
smallest eigenvalue of the translational block of ``K_C`` itself (the index vjm_pin 0.1
reported) is the stiffness with the end's rotations *held*; freeing them can only soften
(Schur complement), e.g. 124 N/mm instead of 247 N/mm for the default ur5.

Non-symmetric K_C. A dead moment makes K_C non-symmetric (see :mod:`vjm_pin.kinematics.chain`).
Only the component of the displacement along the force does work with it, so only the
symmetric part of ``C_tt`` enters ``k(û)``; the displacement ``C_tt û`` itself need not be
parallel to ``û``.

Edge cases, never a silent wrong number:

- ``sym(C_tt)`` not positive definite: a dead force along some direction moves the end
  *backwards* (negative directional stiffness: the loaded end is not stable when loaded by
  a force). The reported direction is then that of the most negative eigenvalue and the
  stiffness ``1/λ_min < 0``; ``kind = "negative"``.
- K_C singular on the task rows: the end moves along some task direction without any
  force change (a mechanism of the passive joints, or a critical point). Those directions
  are listed in ``free``; when one has a translational part the weakest stiffness is 0 along
  it (``kind = "free"``).
- A singular pose (:func:`lost_directions`): the joints cannot move the end along some
  direction to first order there, so that direction is missing from the task (a model
  built at that pose, e.g. ``vjm_pin.model.robots.default_task``) and K_C has no stiffness for
  it: its zero row is *not* a zero stiffness. The caller passes those directions in
  ``lost`` so that they are reported with the index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vjm_pin.exceptions import InputError
from vjm_pin.model.format import COMPONENTS, VjmModel

#: Relative tolerance (on the equilibrated matrix) below which a singular value of K_C
#: counts as zero.
SINGULAR_TOL = 1e-10
#: Perturbation (rad, and m per m of chain size) of the configuration used by
#: :func:`lost_directions` to find the generic rank of the end Jacobian near a pose.
LOST_PROBE = 1e-3

KINDS = ("compliance", "negative", "free")


@dataclass(frozen=True)
class WeakestDirection:
    """The weakest translational stiffness of the end, the end free in all other task components.

    Attributes:
        stiffness: Directional stiffness ``1 / (ûᵀ C_tt û)`` along ``direction`` (N/m): the
            smallest positive one (``kind == "compliance"``), the negative one of the most
            negative compliance (``"negative"``) or 0 (``"free"``).
        direction: (3,) unit vector û, world axes (its largest entry positive); zero along
            translational components outside the task.
        kind: One of :data:`KINDS` (see the module docstring).
        definition: One sentence naming the quantity, for reports.
        compliance_eigenvalues: (k,) ascending eigenvalues of ``sym(C_tt)`` (m/N) over the k
            translational task components; empty when ``kind == "free"``.
        stiffness_rotations_held: Smallest eigenvalue of the symmetric part of the
            translational block of K_C (N/m): the weakest stiffness when all other task
            components (the rotations) are held; for comparison.
        components: The translational task components considered (subset of ``x y z``).
        free: Task directions along which K_C is singular (the end moves there without a
            force change), each named as a combination of task components.
        lost: Directions lost at a singular pose (see :func:`lost_directions`), as given.
    """

    stiffness: float
    direction: np.ndarray
    kind: str
    definition: str
    compliance_eigenvalues: np.ndarray
    stiffness_rotations_held: float
    components: tuple[str, ...]
    free: tuple[str, ...] = ()
    lost: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got '{self.kind}'")
        if np.asarray(self.direction).shape != (3,):
            raise ValueError("direction must have shape (3,)")

    def to_dict(self) -> dict:
        """JSON-ready mapping (SI units)."""
        return {
            "stiffness": float(self.stiffness),
            "direction": np.asarray(self.direction, float),
            "kind": self.kind,
            "definition": self.definition,
            "compliance_eigenvalues": np.asarray(self.compliance_eigenvalues, float),
            "stiffness_rotations_held": float(self.stiffness_rotations_held),
            "components": list(self.components),
            "free_directions": list(self.free),
            "lost_directions": list(self.lost),
        }


def name_direction(v: np.ndarray, components) -> str:
    """A direction ``v`` over ``components`` (names), as text: ``"rx"`` when one component
    carries it (to 1e-6), else ``"0.707 x − 0.707 rz"``; the sign is fixed so that the
    largest entry is positive."""
    v = np.asarray(v, float)
    v = v / np.linalg.norm(v)
    if v[np.argmax(np.abs(v))] < 0:
        v = -v
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) >= 1 - 1e-6:
        return str(components[i])
    terms = [(c, a) for c, a in zip(components, v) if abs(a) >= 5e-4]
    out = ""
    for k, (c, a) in enumerate(terms):
        sign = "−" if a < 0 else ("+" if k else "")
        out += f"{' ' if k else ''}{sign}{' ' if k else ''}{abs(a):.3g} {c}"
    return out


def _scaling(k: np.ndarray) -> np.ndarray:
    """Diagonal ``d`` with ``diag(d) K diag(d)`` of unit row/column max-norm (one Ruiz sweep
    on ``max(|K|, |K|ᵀ)``): K_C mixes N/m, N and N·m/rad entries."""
    a = np.abs(k)
    r = np.maximum(a, a.T).max(axis=1)
    r[r == 0] = 1.0
    return 1.0 / np.sqrt(r)


def _task_matrix(K_C_task, task):
    """``(task, K, translational rows)`` checked: (m, m), finite, at least one translation."""
    task = [int(c) for c in task]
    k = np.asarray(K_C_task, dtype=float)
    m = len(task)
    if k.shape != (m, m):
        raise InputError(
            f"K_C on the task must be ({m}, {m}) for task {[COMPONENTS[c] for c in task]}, got {k.shape}"
        )
    if not np.all(np.isfinite(k)):
        raise InputError("K_C contains NaN or infinite values")
    tt = [i for i, c in enumerate(task) if c < 3]
    if not tt:
        raise InputError(f"task {[COMPONENTS[c] for c in task]} has no translational component")
    return task, k, tt


def _singular_directions(k: np.ndarray, tt):
    """Scaling ``d``, scaled ``S = diag(d) K diag(d)``, the right null directions of ``K``
    (motion without force) and the translational parts of the right and left ones (a force
    with no equilibrium), each relative to the size of its direction."""
    d = _scaling(k)
    s = k * np.multiply.outer(d, d)
    u, sv, vt = np.linalg.svd(s)
    smax = sv.max() if sv.size else 0.0
    null = sv <= SINGULAR_TOL * max(smax, 1e-300)
    if smax == 0.0:
        null[:] = True
    right = d[:, None] * vt[null].T  # K v = 0  <=>  S (v / d) = 0
    left = d[:, None] * u[:, null]  # wᵀ K = 0
    trans = []
    for a in (right, left):
        for v in a.T:
            vn = v / np.linalg.norm(v)
            if np.linalg.norm(vn[tt]) > 1e-8:
                trans.append(vn[tt])
    return d, s, right, trans


def weakest_translation(K_C_task: np.ndarray, task, lost=()) -> WeakestDirection:
    """Weakest translational stiffness of the end, free in all other task components.

    See the module docstring: ``k_min = 1 / λ_max(sym C_tt)``, ``C = K_C⁻¹`` on the task rows.

    Args:
        K_C_task: (m, m) loaded Cartesian stiffness on the task components (eq. 30; N/m,
            N/rad, N·m/m, N·m/rad), e.g. :attr:`StiffnessResult.task_stiffness`.
        task: The m task component indices into ``(x, y, z, rx, ry, rz)``, ascending as in
            :attr:`VjmModel.task`.
        lost: Names of directions lost at a singular pose (:func:`lost_directions`), carried
            into the result.

    Raises:
        InputError: a matrix of the wrong shape or with NaN/inf, a task without a
            translational component.
    """
    task, k, tt = _task_matrix(K_C_task, task)
    names = [COMPONENTS[c] for c in task]
    comps = tuple(names[i] for i in tt)
    blk = k[np.ix_(tt, tt)]
    held = float(np.linalg.eigvalsh(0.5 * (blk + blk.T))[0])
    d, s, right, trans = _singular_directions(k, tt)
    free = tuple(name_direction(v, names) for v in right.T)

    def world(vec):
        out = np.zeros(3)
        out[[task[i] for i in tt]] = vec
        if out[np.argmax(np.abs(out))] < 0:
            out = -out
        return out / np.linalg.norm(out)

    lost = tuple(str(x) for x in lost)
    if trans:
        w = np.linalg.svd(np.array(trans).T)[0][:, 0]
        return WeakestDirection(
            0.0,
            world(w),
            "free",
            "weakest translational stiffness (end free to rotate): zero, K_C is singular and the end "
            "moves along this direction without a force change",
            np.zeros(0),
            held,
            comps,
            free,
            lost,
        )
    # compliance on the task rows (generalised inverse when only non-translational directions
    # are singular: the translational displacement under a force is then still unique)
    c = d[:, None] * np.linalg.pinv(s, rcond=SINGULAR_TOL) * d[None, :]
    ctt = c[np.ix_(tt, tt)]
    ev, vec = np.linalg.eigh(0.5 * (ctt + ctt.T))
    big = max(float(np.abs(ev).max()), 1e-300)
    if ev[0] < -1e-9 * big:
        return WeakestDirection(
            float(1.0 / ev[0]),
            world(vec[:, 0]),
            "negative",
            "weakest translational stiffness (end free to rotate): negative, a dead force along this "
            "direction moves the end backwards (K_C not positive definite)",
            ev,
            held,
            comps,
            free,
            lost,
        )
    return WeakestDirection(
        float(1.0 / ev[-1]) if ev[-1] > 0 else float("inf"),
        world(vec[:, -1]),
        "compliance",
        "weakest translational stiffness (end free to rotate): 1/λ_max of the symmetric part of the "
        "translational block of the compliance K_C⁻¹",
        ev,
        held,
        comps,
        free,
        lost,
    )


def lost_directions(
    vm: VjmModel, x: np.ndarray | None = None, *, outside_task: bool = True, seed: int = 0, kin=None
) -> tuple[np.ndarray, ...]:
    """Directions in which the end cannot move to first order at ``x`` although it can at
    nearby configurations: the directions a singular pose loses.

    A lost direction inside the task makes the matrix of eq. (28) singular, which the
    stiffness code reports (:class:`~vjm_pin.exceptions.SingularStiffness`) when it is still
    singular at the equilibrium; one the task leaves out (a model built at that pose drops it,
    ``vjm_pin.model.robots.default_task``) leaves a zero row in K_C that is not a zero stiffness.
    With ``outside_task`` (default) only the latter are returned: those with a part outside
    the task components.

    The (6, n) end Jacobian over the spring and passive coordinates (``LOCAL_WORLD_ALIGNED``)
    is compared at ``x`` and at a seeded perturbation of size :data:`LOST_PROBE`: the
    left-null directions at ``x`` that are not (near) left-null directions at the perturbed
    configuration are lost. Directions that no configuration reaches (e.g. out of the plane
    of a planar chain) are not reported.

    Args:
        vm: The model. x: (nq,) configuration (default the unloaded reference pose).
        outside_task: Return only the lost directions with a component outside ``vm.task``.
        seed: Seed of the perturbation.
        kin: A :class:`~vjm_pin.kinematics.chain.Kinematics` of ``vm`` to reuse (creating one
            costs seconds for finely subdivided models).

    Returns:
        Unit 6-vectors over ``(x, y, z, rx, ry, rz)`` (m and rad mixed, as in the Jacobian);
        name them with ``name_direction(v, COMPONENTS)``.
    """
    from vjm_pin.kinematics.chain import Kinematics

    if outside_task and len(vm.task) == 6:
        return ()  # nothing is outside the task
    x = vm.reference if x is None else np.asarray(x, float)
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    if free.size == 0:
        return ()
    kin = Kinematics(vm.model, vm.frame_id) if kin is None else kin
    rng = np.random.default_rng(seed)
    xp = np.array(x, float)
    xp[free] += LOST_PROBE * rng.standard_normal(free.size)

    def left_null(jac):
        # U and the singular values of the (6, n) J from the small R of Jᵀ = QR (J = Rᵀ Qᵀ)
        u, s, _ = np.linalg.svd(np.linalg.qr(jac.T, mode="r").T, full_matrices=True)
        rank = int(np.sum(s > 1e-9 * max(s.max() if s.size else 0.0, 1e-300)))
        return u[:, rank:]

    n0 = left_null(kin.evaluate(x, hessian=False).jacobian[:, free])
    n1 = left_null(kin.evaluate(xp, hessian=False).jacobian[:, free])
    extra = n0.shape[1] - n1.shape[1]
    if extra <= 0:
        return ()
    rest = n0 - n1 @ (n1.T @ n0)  # the part of the null space at x not seen nearby
    w = np.linalg.svd(rest)[0][:, :extra]
    out = [v.copy() for v in w.T]
    if outside_task:
        other = [c for c in range(6) if c not in vm.task]
        out = [v for v in out if np.linalg.norm(v[other]) > 1e-6]
    return tuple(out)
