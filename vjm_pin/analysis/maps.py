"""Workspace maps: deflection and stiffness indices over many poses, on local cores or Dask.

Every pose is evaluated by the same pure function (:func:`evaluate_pose`) from the model's
URDF text, the joint values, the wrench and the options, so the results do not depend on
the backend, the number of workers or the chunking: ``serial``, ``local`` (a process pool
on all cores) and ``dask`` (``dask.distributed``; a local cluster when no scheduler
address is given) agree bit for bit (``tests/test_maps.py``).

Models of every kind. A serial chain is evaluated at the joint values of the pose
(:class:`~vjm_pin.solver.EquilibriumSolver`); an open chain of springs and motors loaded at its
end only (ur5 with actuator or link springs) has all poses of a chunk solved in lockstep
(:mod:`vjm_pin.analysis.batched`: the same Newton iteration on stacked arrays, one Pinocchio
Jacobian per pose per iteration; poses it cannot vouch for go to the per-pose path, and each
pose's numbers do not depend on its chunk, so the backends still agree bit for bit). From
:data:`JIT_MIN_POSES` poses on, such a map uses the compiled kernels (numba; ``VJM_PIN_JIT=0``:
never), a choice made once per map and passed to every worker. A worker sends its chunk back as
columns (:class:`PoseRows`). A mechanism with loop closures (a four-bar, the
Orthoglide) is mapped over its **actuated** joints: at each pose it is first re-assembled
(:mod:`vjm_pin.analysis.assembly`: passive joints found by continuation from the reference so
that every closure holds, springs at rest), then loaded and solved by
:class:`~vjm_pin.solver.mechanism.MechanismSolver`, the solver of ``analyze`` (its equilibrium,
eq. 23 verdict and the bordered eq. 28 K_C). Dead loads anywhere (``loads``; the CLI's ``--load``,
``--payload``) and link weights take the same mechanism path, as in ``analyze``.

Output. :func:`run_map` returns the whole map (:class:`MapResult`); :func:`stream_map` writes
the rows to a CSV file as chunks finish (:class:`CsvStream`, pose order, renamed into place at
the end) and keeps only a :class:`MapSummary`, for maps of millions of poses. Plots:
:func:`vjm_pin.viz.plots.save_map_plot`.

Indices at each pose (the end wrench ``F`` of eq. 11 and, optionally, dead loads at frames
and link weights):

``deflection``        (6,) end displacement (m, rad), world axes.
``k_along``           translational stiffness along the force direction ``f̂`` (N/m):
                      ``1 / (f̂ᵀ C_tt f̂)`` with ``C = K_C⁻¹`` the loaded compliance (eq. 30);
                      rotations are free, so it is the stiffness the force really meets.
``k_min``             weakest translational stiffness, the end free to rotate (N/m):
                      ``1 / λ_max(sym C_tt)`` (:func:`vjm_pin.analysis.indices.weakest_translation`;
                      0 where K_C is singular along a translation).
``stable``            verdict of eq. (23) at the loaded equilibrium.
``status``            ``ok``, ``singular`` (no finite stiffness there, e.g. a singular pose),
                      ``no-equilibrium`` (the load exceeds what the pose can carry) or
                      ``no-assembly`` (a closed mechanism that cannot be assembled at these
                      actuator positions from its reference: out of the workspace, or beyond
                      a singular configuration; every index NaN, ``p0`` too).
"""

from __future__ import annotations

import csv
import itertools
import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import InputError
from vjm_pin.model.format import VjmModel

STATUS = ("ok", "singular", "no-equilibrium", "no-assembly")
BACKENDS = ("serial", "local", "dask")
#: Most poses one map may hold (about 100 bytes each in memory and 300 in a CSV file).
MAX_POSES = 10_000_000
#: Most local worker processes per core (more only adds memory and start-up time).
MAX_WORKERS_PER_CORE = 16


# ----------------------------------------------------------------------------- poses
def mapped_joints(vm: VjmModel) -> list[str]:
    """The joints a map varies: the actuated joints with an actuator spring (the robot's
    motors; for a closed mechanism its actuators), in configuration order."""
    act = {g.joints[0] for g in vm.springs if g.link is None and len(g.joints) == 1}
    return [n for n in vm.joint_names if n in act and vm.roles[n] == "actuated"]


def joint_limits(vm: VjmModel, names) -> np.ndarray:
    """(n, 2) position limits of ``names`` from the URDF (rad, m); unlimited/continuous
    joints (|limit| ≥ 100) get [−π, π]."""
    m = vm.model
    out = []
    for n in names:
        j = m.getJointId(n)
        i = m.joints[j].idx_q
        lo, hi = float(m.lowerPositionLimit[i]), float(m.upperPositionLimit[i])
        if (
            not (math.isfinite(lo) and math.isfinite(hi))
            or hi <= lo
            or max(abs(lo), abs(hi)) >= 100
        ):
            lo, hi = -math.pi, math.pi
        out.append((lo, hi))
    return np.array(out, dtype=float).reshape(-1, 2)


def _urdf_limits(vm: VjmModel, name: str):
    """(lo, hi) position limits of joint ``name`` from the URDF, or None when the joint has
    none (infinite, empty, or the |limit| ≥ 100 placeholders of unlimited joints)."""
    m = vm.model
    i = m.joints[m.getJointId(name)].idx_q
    lo, hi = float(m.lowerPositionLimit[i]), float(m.upperPositionLimit[i])
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo or max(abs(lo), abs(hi)) >= 100:
        return None
    return lo, hi


def _check_count(n: int, what: str) -> None:
    if n > MAX_POSES:
        raise InputError(
            f"{what}: {n:,} poses is more than one map holds ({MAX_POSES:,}); split the map"
        )


def sample_poses(vm: VjmModel, n: int, seed: int = 0, names=None) -> tuple[list[str], np.ndarray]:
    """``n`` poses drawn uniformly within the joint limits (seeded: reproducible).

    Raises:
        InputError: ``n`` not an integer in 1 … :data:`MAX_POSES`, ``seed`` not an integer
            ≥ 0, or the model has no motor joint to vary.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"n must be a positive integer (poses to sample), got {n!r}")
    _check_count(int(n), "n")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"seed must be an integer ≥ 0, got {seed!r}")
    names = list(names or mapped_joints(vm))
    if not names:
        raise InputError(
            f"model '{vm.name}' has no actuated joint with an actuator spring to sample; "
            "give the joints to vary (names, or a grid of poses: grid_poses)"
        )
    lim = joint_limits(vm, names)
    rng = np.random.default_rng(int(seed))
    return names, lim[:, 0] + rng.random((int(n), len(names))) * (lim[:, 1] - lim[:, 0])


def parse_grid(items) -> dict[str, np.ndarray]:
    """``["NAME=LO:HI:N", ...]`` → {name: N values from LO to HI}.

    Raises:
        InputError: an item not of the form NAME=LO:HI:N, bounds not finite, LO > HI,
            N < 1, N > 1 with LO = HI, a joint given twice, or more than :data:`MAX_POSES`
            poses in all.
    """
    out = {}
    total = 1
    for it in items or []:
        try:
            name, rng_ = str(it).split("=", 1)
            lo, hi, n = rng_.split(":")
            lo_f, hi_f, n_i = float(lo), float(hi), int(n)
        except ValueError:
            raise InputError(f"grid item '{it}': expected NAME=LO:HI:N (N an integer)") from None
        if not name:
            raise InputError(f"grid item '{it}': no joint name before '='")
        if name in out:
            raise InputError(f"grid: joint '{name}' given twice")
        if n_i < 1 or not (math.isfinite(lo_f) and math.isfinite(hi_f)):
            raise InputError(f"grid {name}: need finite bounds and N ≥ 1, got '{rng_}'")
        if lo_f > hi_f:
            raise InputError(f"grid {name}: LO {lo_f:g} is above HI {hi_f:g}")
        if lo_f == hi_f and n_i > 1:
            raise InputError(
                f"grid {name}: LO = HI = {lo_f:g} gives {n_i} equal values; use N = 1"
            )
        total *= n_i
        _check_count(total, "grid")
        out[name] = np.linspace(lo_f, hi_f, n_i)
    return out


def grid_poses(vm: VjmModel, grid: dict) -> tuple[list[str], np.ndarray]:
    """Cartesian product of the grid values; the other joints stay at the reference pose.

    Raises:
        JointNotFound: an unknown joint. RoleError: a virtual spring joint (its position
            is its rest value). InputError: an empty grid, values outside the joint's
            URDF limits, or more than :data:`MAX_POSES` poses.
    """
    from vjm_pin.exceptions import RoleError

    if not grid:
        raise InputError("grid: no joint given (NAME=LO:HI:N ...)")
    total = 1
    for n, vals in grid.items():
        vm.joint_index(n)  # JointNotFound on an unknown name
        if vm.roles[n] == "spring":
            raise RoleError(
                f"grid {n}: a virtual spring joint cannot be set (its position is its rest value)"
            )
        vals = np.asarray(vals, dtype=float).reshape(-1)
        lim = _urdf_limits(vm, n)
        if lim is not None and (vals.min() < lim[0] or vals.max() > lim[1]):
            raise InputError(
                f"grid {n}: values {vals.min():g} … {vals.max():g} leave the joint limits "
                f"[{lim[0]:g}, {lim[1]:g}] of the URDF"
            )
        total *= vals.size
    _check_count(total, "grid")
    names = list(grid)
    return names, np.array(list(itertools.product(*[grid[n] for n in names])), dtype=float).reshape(
        -1, len(names)
    )


# ----------------------------------------------------------------------------- one pose
_MODEL_CACHE: dict = {}
#: One Kinematics (one pin.Data) per Pinocchio model and end frame in this process: every
#: pose of a map shares the model (``with_positions`` changes only the reference), so a
#: worker creates its Pinocchio workspace once, not once per pose (issue 14).
_KIN_CACHE: dict = {}
# (every cache of this module is per thread: a Dask worker with several threads evaluates poses
# concurrently, and a pin.Data must not be shared between them)


def _shared_kinematics(model, frame_id: int):
    from vjm_pin.kinematics.chain import Kinematics

    key = (id(model), int(frame_id), threading.get_ident())  # a pin.Data is not thread-safe
    hit = _KIN_CACHE.get(key)
    if hit is None or hit[0] is not model:
        if len(_KIN_CACHE) >= 8:
            _KIN_CACHE.clear()
        hit = (model, Kinematics(model, frame_id))  # the model is kept: its id stays unique
        _KIN_CACHE[key] = hit
    return hit[1]


def _model_from_text(text: str) -> VjmModel:
    key = hash(text)
    vm = _MODEL_CACHE.get(key)
    if vm is None or vm.urdf != text:
        from vjm_pin.model.format import load_vjm

        vm = load_vjm(text)
        _MODEL_CACHE.clear()
        _MODEL_CACHE[key] = vm
    return vm


def evaluate_pose(
    vm: VjmModel, names, values, wrench, gravity=None, method: str = "eq30", loads=()
) -> dict:
    """Deflection and stiffness indices of ``vm`` at the pose ``names = values`` under the
    end ``wrench`` (6,), the dead ``loads`` (:class:`~vjm_pin.kinematics.dead_loads.Load`)
    and, if ``gravity`` (3,) is given, the link weights. Never raises for a pose that cannot
    be analysed: ``status`` says why. Mechanisms (:func:`uses_mechanism_solver`) are
    re-assembled at the pose and solved by :class:`~vjm_pin.solver.mechanism.MechanismSolver`."""
    from vjm_pin.solver.threads import single_blas_thread

    with single_blas_thread():  # one BLAS thread inside (vjm_pin.solver.threads)
        if uses_mechanism_solver(vm, gravity, loads):
            return _evaluate_mechanism(vm, names, values, wrench, gravity, tuple(loads))
        return _evaluate_pose(vm, names, values, wrench, gravity, method)


def uses_mechanism_solver(vm: VjmModel, gravity=None, loads=()) -> bool:
    """Whether a map of ``vm`` solves its poses with :class:`~vjm_pin.solver.mechanism.MechanismSolver`
    (as ``analyze``): loop closures, dead loads at frames (a payload too) or link weights. An open
    chain loaded at its end only takes the serial solvers."""
    return bool(vm.closures) or bool(len(loads)) or gravity is not None


def _empty_row(p0=None) -> dict:
    return {
        "p0": np.full(3, np.nan) if p0 is None else p0,
        "deflection": np.full(6, np.nan),
        "k_along": np.nan,
        "k_min": np.nan,
        "stable": False,
        "status": "ok",
    }


#: One :class:`~vjm_pin.analysis.assembly.Assembler` per model and joint set in this process
#: (its lattice memo does not change any number: see :mod:`vjm_pin.analysis.assembly`).
_ASSEMBLER_CACHE: dict = {}


def _shared_assembler(vm: VjmModel, names):
    from vjm_pin.analysis.assembly import Assembler

    key = (id(vm), tuple(names), threading.get_ident())
    hit = _ASSEMBLER_CACHE.get(key)
    if hit is None or hit[0] is not vm:
        if len(_ASSEMBLER_CACHE) >= 4:
            _ASSEMBLER_CACHE.clear()
        hit = (vm, Assembler(vm, names))  # the model is kept: its id stays unique
        _ASSEMBLER_CACHE[key] = hit
    return hit[1]


#: One :class:`~vjm_pin.solver.mechanism.MechanismSolver` (its ``pin.Data``) per model, loads and
#: gravity in this process; each pose gets a copy at its reference
#: (:meth:`~vjm_pin.solver.mechanism.MechanismSolver.at_reference`), not a new Pinocchio workspace.
_SOLVER_CACHE: dict = {}


def _base_solver(vm: VjmModel, loads=(), gravity=None):
    """This process's MechanismSolver of ``vm`` (at the file's reference) for these loads."""
    from vjm_pin.solver.mechanism import MechanismSolver

    key = (
        id(vm),
        threading.get_ident(),
        tuple((ld.frame, tuple(ld.wrench.tolist())) for ld in loads),
        None if gravity is None else tuple(np.asarray(gravity, float).tolist()),
    )
    hit = _SOLVER_CACHE.get(key)
    if hit is None or hit[0] is not vm:
        if len(_SOLVER_CACHE) >= 4:
            _SOLVER_CACHE.clear()
        hit = (vm, MechanismSolver(vm, loads, None if gravity is None else np.asarray(gravity, float)))
        _SOLVER_CACHE[key] = hit
    return hit[1]


def assembled_model(vm: VjmModel, names, values) -> VjmModel | None:
    """``vm`` with the joints ``names`` at ``values`` and, for a closed mechanism, its passive
    joints re-assembled (:class:`~vjm_pin.analysis.assembly.Assembler`): a model whose reference
    configuration satisfies every closure with the springs at rest. None when the mechanism
    cannot be assembled there."""
    positions = {n: float(x) for n, x in zip(names, values)}
    if vm.closures:
        asm = _shared_assembler(vm, names).assemble([positions[n] for n in names])
        if not asm.ok:
            return None
        positions.update({n: float(asm.x[i]) for n, i in zip(vm.q_names, vm.q_idx)})
    return vm.with_positions(positions)


def _evaluate_mechanism(vm: VjmModel, names, values, wrench, gravity, loads) -> dict:
    """One pose of a mechanism: re-assembled, then loaded (:class:`MechanismSolver`, every task
    component loaded by ``wrench``, the dead ``loads`` and link weights)."""
    from vjm_pin.exceptions import NoEquilibrium, SingularStiffness

    v = assembled_model(vm, names, values)
    if v is None:
        row = _empty_row()
        row["status"] = "no-assembly"
        return row
    solver = _base_solver(vm, loads, gravity).at_reference(v)
    row = _empty_row(solver.p0.copy())
    w = np.asarray(wrench, float)
    try:
        res = solver.solve(wrench=w, x0=v.reference)
        k = solver.stiffness(res).stiffness
    except SingularStiffness:
        row["status"] = "singular"
        return row
    except NoEquilibrium:
        row["status"] = "no-equilibrium"
        return row
    row["deflection"] = res.deflection
    row["stable"] = bool(res.stable)
    row["k_along"], row["k_min"] = stiffness_indices(k, w, v.task)
    return row


def _evaluate_pose(vm: VjmModel, names, values, wrench, gravity, method) -> dict:
    """One pose of an open chain loaded at its end only: :meth:`EquilibriumSolver.solve_wrench`
    (every task component loaded, from the unloaded reference) and the loaded K_C (eq. 28/30)
    there. The reference of :mod:`vjm_pin.analysis.batched`, and the path of chains with passive
    joints and of the poses the batched path hands back."""
    from vjm_pin.exceptions import NoEquilibrium, SingularStiffness
    from vjm_pin.solver import loaded_stiffness

    v = _pose_setter(vm).model_at(names, values)
    solver = _serial_solver(vm, v)
    row = _empty_row(solver.p0.copy())
    w = np.asarray(wrench, float)
    try:
        res = solver.solve_wrench(w)
        k = loaded_stiffness(v, res, method, kin=solver.kin).stiffness
    except SingularStiffness:
        row["status"] = "singular"
        return row
    except NoEquilibrium:
        row["status"] = "no-equilibrium"
        return row
    row["deflection"] = res.deflection
    row["stable"] = bool(res.stable)
    row["k_along"], row["k_min"] = stiffness_indices(k, w, v.task)
    return row


class _PoseSetter:
    """:meth:`VjmModel.with_positions` for the many poses of one map: the joint indices, roles
    and spring groups of the varied joints are looked up once per model, not once per pose
    (``VjmModel.joint_names`` builds a list of the Pinocchio names at every call)."""

    def __init__(self, vm: VjmModel):
        self.vm = vm
        names = vm.joint_names
        self.index = {n: i for i, n in enumerate(names)}
        theta = {int(i): k for k, i in enumerate(vm.theta_idx)}
        self.theta_pos = {n: theta.get(i) for n, i in self.index.items() if vm.roles[n] == "actuated"}
        self.group = {g.joints[0]: k for k, g in enumerate(vm.springs) if len(g.joints) == 1}

    def arrays_at(self, names, values) -> tuple[np.ndarray, np.ndarray]:
        """(reference, θ₀) of the model with ``names`` at ``values`` (no checks: the map checked
        the names, and values come from a finite (N, n) array)."""
        vm = self.vm
        ref = vm.reference.copy()
        theta0 = vm.theta0.copy()
        for n, x in zip(names, values):
            ref[self.index[n]] = x
            k = self.theta_pos.get(n)
            if k is not None:
                theta0[k] = x
        return ref, theta0

    def model_at(self, names, values) -> VjmModel:
        """The same model as ``vm.with_positions(dict(zip(names, values)))``."""
        from dataclasses import replace

        ref, theta0 = self.arrays_at(names, [float(x) for x in values])
        springs = list(self.vm.springs)
        for n, x in zip(names, values):
            g = self.group.get(n)
            if g is not None and n in self.theta_pos:
                springs[g] = replace(springs[g], rest=np.array([float(x)]))
        return replace(self.vm, reference=ref, theta0=theta0, springs=tuple(springs))


_SETTER_CACHE: dict = {}


def _pose_setter(vm: VjmModel) -> _PoseSetter:
    hit = _SETTER_CACHE.get(id(vm))
    if hit is None or hit.vm is not vm:
        if len(_SETTER_CACHE) >= 8:
            _SETTER_CACHE.clear()
        hit = _SETTER_CACHE[id(vm)] = _PoseSetter(vm)  # holds vm: its id stays unique
    return hit


def _serial_solver(vm: VjmModel, v: VjmModel):
    """An :class:`~vjm_pin.solver.EquilibriumSolver` of the pose model ``v`` (``vm`` moved by
    :class:`_PoseSetter`) on this thread's shared :class:`~vjm_pin.kinematics.chain.Kinematics`
    (one ``pin.Data`` per worker, none per pose)."""
    from vjm_pin.solver import EquilibriumSolver

    return EquilibriumSolver(v, _kin=_shared_kinematics(vm.model, vm.frame_id))


def stiffness_indices(k6: np.ndarray, wrench: np.ndarray, task) -> tuple[float, float]:
    """(k_along, k_min) of the module docstring from the (6, 6) ``K_C`` (N/m)."""
    t = list(task)
    tt = [i for i, c in enumerate(t) if c < 3]
    if not tt:
        return math.nan, math.nan
    kt = np.asarray(k6)[np.ix_(t, t)]
    try:
        c = np.linalg.inv(kt)
    except np.linalg.LinAlgError:
        c = None
    f = np.asarray(wrench, float)[[t[i] for i in tt]]
    nf = np.linalg.norm(f)
    k_along = math.nan
    if nf > 0 and c is not None:
        fh = f / nf
        k_along = float(1.0 / (fh @ c[np.ix_(tt, tt)] @ fh))
    from vjm_pin.analysis.indices import weakest_translation

    return k_along, weakest_translation(kt, t).stiffness


#: Private switch: False evaluates every pose by the per-pose path (the reference that
#: ``tests/test_map_batched.py`` compares the batched path with).
_batching = True


def _chunk_worker(text, names, wrench, gravity, method, loads, jit, csv_text, chunk) -> PoseRows:
    """Evaluate a chunk of poses (runs in a worker process); its rows as columns. ``jit``: the
    map's choice of compiled kernels (:func:`_use_jit`), the same in every worker; ``csv_text``:
    also the rows' CSV text (:func:`stream_map`: formatted by the workers, in parallel)."""
    rows = _chunk_rows(text, names, wrench, gravity, method, loads, jit, chunk)
    if csv_text:
        rows.text = _csv_lines(_csv_floats(chunk, rows), rows.stable, np.asarray(STATUS)[rows.status])
    return rows


def _chunk_rows(text, names, wrench, gravity, method, loads, jit, chunk) -> PoseRows:
    """The rows of a chunk (:func:`_chunk_worker`)."""
    from vjm_pin.analysis.batched import batch_applicable, shared_chain
    from vjm_pin.exceptions import VjmError
    from vjm_pin.solver.threads import single_blas_thread

    vm = _model_from_text(text)
    try:
        if jit:  # the per-pose solver's compiled kernel too (vjm_pin.solver.kernel): one arithmetic
            from vjm_pin.solver import kernel

            if not kernel.load():
                raise VjmError("this map needs numba in every worker (or VJM_PIN_JIT=0 everywhere)")
        with single_blas_thread():  # once per chunk, not per pose
            if _batching and batch_applicable(vm, gravity, loads):
                # all poses of the chunk in lockstep; the few handed back take the per-pose path
                keep, p0, defl, k_along, k_min = shared_chain(vm, jit).solve_arrays(names, chunk, wrench)
                out = PoseRows(p0, defl, k_along, k_min, keep.copy(), np.zeros(len(keep), np.uint8))
                for i in np.flatnonzero(~keep):
                    out.put(i, evaluate_pose(vm, names, chunk[i], wrench, gravity, method, loads))
                return out
            return PoseRows.from_dicts([evaluate_pose(vm, names, row, wrench, gravity, method, loads) for row in chunk])
    except VjmError as e:  # subclasses with extra constructor arguments do not unpickle
        raise VjmError(str(e)) from None


class PoseRows:
    """The rows of one chunk of a map as columns (what a worker sends back: a few arrays to
    pickle, not a dict per pose).

    Attributes:
        p0: (n, 3) m.
        deflection: (n, 6) m, rad.
        k_along: (n,) N/m.
        k_min: (n,) N/m.
        stable: (n,) bool.
        status: (n,) uint8, index into :data:`STATUS`.
        text: The rows as CSV lines for :func:`stream_map`, or None.
    """

    __slots__ = ("deflection", "k_along", "k_min", "p0", "stable", "status", "text")

    def __init__(self, p0, deflection, k_along, k_min, stable, status, text=None):
        self.p0, self.deflection, self.k_along, self.k_min = p0, deflection, k_along, k_min
        self.stable, self.status = stable, status
        self.text = text  # the rows as CSV text (streamed maps), or None

    def __len__(self) -> int:
        return len(self.status)

    def put(self, i: int, row: dict) -> None:
        """Set row ``i`` from a dict of :func:`evaluate_pose`."""
        self.p0[i] = row["p0"]
        self.deflection[i] = row["deflection"]
        self.k_along[i] = row["k_along"]
        self.k_min[i] = row["k_min"]
        self.stable[i] = bool(row["stable"])
        self.status[i] = STATUS.index(row["status"])

    @classmethod
    def empty(cls, n: int) -> PoseRows:
        return cls(
            np.full((n, 3), np.nan), np.full((n, 6), np.nan), np.full(n, np.nan), np.full(n, np.nan),
            np.zeros(n, bool), np.zeros(n, np.uint8),
        )  # fmt: skip

    @classmethod
    def from_dicts(cls, rows) -> PoseRows:
        """The rows (dicts of :func:`evaluate_pose`) as columns; a :class:`PoseRows` as it is."""
        if isinstance(rows, PoseRows):
            return rows
        out = cls.empty(len(rows))
        for i, r in enumerate(rows):
            out.put(i, r)
        return out


# ----------------------------------------------------------------------------- result
@dataclass(frozen=True)
class MapResult:
    """A workspace map.

    Attributes:
        model: Model name. frame: End frame. joints: The varied joint names.
        poses: (N, n) joint values (rad, m).
        p0: (N, 3) unloaded end position (m, world).
        deflection: (N, 6) end deflection (m, rad; world); NaN where ``status`` is not ok.
        k_along: (N,) stiffness along the force (N/m). k_min: (N,) weakest translational
            stiffness, the end free to rotate (N/m; see the module docstring).
        stable: (N,) eq. (23) verdict. status: (N,) one of :data:`STATUS`.
        wrench: (6,) end wrench (N, N·m). gravity: (3,) m/s² (zeros: none).
        loads: Dead loads at frames (:class:`~vjm_pin.kinematics.dead_loads.Load`).
    """

    model: str
    frame: str
    joints: tuple
    poses: np.ndarray
    p0: np.ndarray
    deflection: np.ndarray
    k_along: np.ndarray
    k_min: np.ndarray
    stable: np.ndarray
    status: np.ndarray
    wrench: np.ndarray
    gravity: np.ndarray
    loads: tuple = ()

    @property
    def ok(self) -> np.ndarray:
        return self.status == "ok"

    def columns(self) -> dict[str, np.ndarray]:
        """Flat columns (name → (N,) array) of the CSV file."""
        cols = {n: self.poses[:, i] for i, n in enumerate(self.joints)}
        for i, a in enumerate("xyz"):
            cols[f"p0_{a}_m"] = self.p0[:, i]
        for i, a in enumerate(("dx_m", "dy_m", "dz_m", "rx_rad", "ry_rad", "rz_rad")):
            cols[a] = self.deflection[:, i]
        cols["deflection_m"] = np.linalg.norm(self.deflection[:, :3], axis=1)  # SI, as the JSON
        cols["rotation_rad"] = np.linalg.norm(self.deflection[:, 3:], axis=1)
        cols["k_along_N_per_m"] = self.k_along
        cols["k_min_N_per_m"] = self.k_min
        cols["stable"] = self.stable
        cols["status"] = self.status
        return cols

    def to_csv(self, path) -> None:
        """Write the columns of :meth:`columns` as CSV, atomically (a temporary file renamed
        over ``path``: an interrupted write leaves no half file)."""
        from vjm_pin.outputs import atomic_output

        cols = self.columns()
        floats = [c for k, c in cols.items() if k not in ("stable", "status")]
        with atomic_output(path, "w") as fh:
            csv.writer(fh).writerow(list(cols))
            for i in range(0, self.poses.shape[0], 10_000):  # the text of 10⁴ rows at a time
                sl = slice(i, i + 10_000)
                fh.write(_csv_lines(np.column_stack([c[sl] for c in floats]), self.stable[sl], self.status[sl]))

    def to_npz(self, path) -> None:
        """Write the arrays to a NumPy ``.npz`` archive at ``path`` (exactly that name),
        atomically."""
        from vjm_pin.outputs import atomic_output

        with atomic_output(path, "wb") as fh:
            np.savez(
                fh,
                model=self.model,
                frame=self.frame,
                joints=np.array(self.joints),
                poses=self.poses,
                p0=self.p0,
                deflection=self.deflection,
                k_along=self.k_along,
                k_min=self.k_min,
                stable=self.stable,
                status=self.status,
                wrench=self.wrench,
                gravity=self.gravity,
                load_frames=np.array([ld.frame for ld in self.loads], dtype=str),
                load_wrenches=np.array([ld.wrench for ld in self.loads], float).reshape(-1, 6),
            )

    def save(self, path) -> None:
        """CSV or NPZ by the file suffix (written atomically)."""
        p = Path(path)
        if p.suffix == ".csv":
            self.to_csv(p)
        elif p.suffix == ".npz":
            self.to_npz(p)
        else:
            raise InputError(f"output file must end in .csv or .npz, got '{p.name}'")


def _csv_value(v):
    if isinstance(v, (np.floating, float)):
        return repr(float(v))
    if isinstance(v, (np.bool_, bool)):
        return int(bool(v))
    return v


# ----------------------------------------------------------------------------- run
def run_map(
    vm: VjmModel,
    names,
    poses: np.ndarray,
    wrench,
    *,
    gravity=None,
    loads=(),
    method: str = "eq30",
    backend: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    progress=None,
) -> MapResult:
    """Evaluate the map over ``poses`` (N, len(names)).

    Args:
        names: The joints the poses set; for a closed mechanism actuated joints only (its
            passive joints are re-assembled at each pose).
        wrench: (6,) or (3,) dead wrench on the task frame (N, N·m; world axes).
        gravity: (3,) gravity (m/s²) for the link weights, or None.
        loads: Dead loads at frames (:class:`~vjm_pin.kinematics.dead_loads.Load`, world axes).
        backend: ``"serial"``, ``"local"`` (process pool, ``workers`` processes, default all
            cores) or ``"dask"`` (``dask.distributed`` client on ``scheduler``, an address
            ``tcp://HOST:PORT``; a local cluster of ``workers`` processes when None).
        chunk: Poses per task (default: about 4 tasks per worker, at most 50 poses, or
            :data:`BATCH_CHUNK` when the chunks are solved in lockstep,
            :mod:`vjm_pin.analysis.batched`).
        progress: Called with the number of poses done after each chunk.

    Raises:
        InputError: bad poses, wrench (a mechanism: components outside the task), loads,
            backend, workers or chunk. FrameNotFound: a load at an unknown frame. RoleError:
            a spring joint in ``names``, or a passive one of a closed mechanism. SchedulerError (an
            InputError): no Dask scheduler at ``scheduler``. MapInterrupted: Ctrl-C; it carries the
            poses finished so far (:mod:`vjm_pin.analysis.map_backends` stops the workers first).
    """
    from vjm_pin.exceptions import MapInterrupted

    names, poses, w, g, loads = _check_problem(vm, names, poses, wrench, gravity, loads)
    n_poses = poses.shape[0]
    out = _Columns(n_poses)
    finished = np.zeros(n_poses, dtype=bool)

    def consume(start, rows):
        out.fill(start, rows)
        finished[start : start + len(rows)] = True  # only now: a chunk cut short is not counted

    try:
        _run_chunks(vm, names, poses, w, g, loads, method, backend, workers, scheduler, chunk, consume, progress)
    except KeyboardInterrupt:
        raise MapInterrupted(out.result(vm, names, poses, w, g, finished, loads), n_poses) from None
    return out.result(vm, names, poses, w, g, np.ones(n_poses, dtype=bool), loads)


#: Default poses per chunk of a map solved in lockstep (:mod:`vjm_pin.analysis.batched`, which
#: splits a chunk into cache-sized blocks itself): large enough that a task's fixed cost (a Dask
#: task costs milliseconds of scheduler and client time) is a few % of its ~0.1–0.5 s of work.
BATCH_CHUNK = 2000


def _run_chunks(vm, names, poses, w, g, loads, method, backend, workers, scheduler, chunk, consume, progress, csv_text=False):
    """Evaluate the checked problem chunk by chunk; ``consume(start, rows)`` for each chunk in
    the calling thread (completion order), ``progress(done)`` after it; ``csv_text``: the workers
    also format the rows as CSV (:attr:`PoseRows.text`)."""
    from vjm_pin.analysis.batched import batch_applicable
    from vjm_pin.analysis.map_backends import run_chunks

    if backend not in BACKENDS:
        raise InputError(f"unknown backend '{backend}'; choose one of {BACKENDS}")
    n_poses = poses.shape[0]
    batched = _batching and batch_applicable(vm, g, loads)
    workers, chunk = _check_workers(workers, chunk, scheduler, n_poses, BATCH_CHUNK if batched else 50)
    jit = _use_jit(batched, n_poses, backend)
    starts = list(range(0, n_poses, chunk))
    done = 0

    def report(k, rows):
        nonlocal done
        consume(starts[k], rows)
        done += len(rows)
        if progress is not None:
            progress(done)

    run_chunks(
        _chunk_worker,
        (vm.urdf, names, w, g, method, loads, jit, csv_text),
        [poses[i : i + chunk] for i in starts],
        report,
        backend=backend,
        workers=workers,
        scheduler=scheduler,
    )


#: Batched maps of at least this many poses use the compiled kernels (numba): loading them costs
#: ~1–2 s per process, which the faster poses repay from a few thousand poses on.
JIT_MIN_POSES = 2000


def _use_jit(batched: bool, n_poses: int, backend: str) -> bool:
    """Whether this map's workers use the compiled kernels (:func:`vjm_pin.analysis.batched.kernel`
    and :mod:`vjm_pin.solver.kernel`): a batched map of :data:`JIT_MIN_POSES` poses or more, numba
    importable and ``VJM_PIN_JIT`` not ``0``. Decided once here and passed to every chunk, so all
    poses of a map take the same arithmetic whatever the backend. For the local pool the kernels
    are compiled (or loaded from the disk cache) before the workers are forked."""
    if not (batched and n_poses >= JIT_MIN_POSES):
        return False
    from vjm_pin.analysis.batched import jit_available, warm_kernel

    if not jit_available():
        return False
    if backend in ("serial", "local"):
        from vjm_pin.solver import kernel

        warm_kernel()
        kernel.load()
    return True


# ----------------------------------------------------------------------------- streaming
@dataclass(frozen=True)
class MapSummary:
    """What :func:`stream_map` keeps of a map written to a CSV file: no per-pose rows, only the
    four magnitudes the summaries need (about 40 bytes a pose, against about 200 in a
    :class:`MapResult` and 300 in the file).

    Attributes:
        model, frame, joints, wrench, gravity, loads: As :class:`MapResult`.
        path: The CSV file written. n_poses: Poses written (all of them, or those finished
            before an interrupt). requested: Poses asked for. poses: (n_poses, k) their joint
            values (the caller's array itself when every pose was written).
        status: (n,) status codes, index into :data:`STATUS` (uint8). stable: (n,) bool.
        deflection_norm, rotation_norm, k_along, k_min: (n,) float (m, rad, N/m, N/m).
    """

    model: str
    frame: str
    joints: tuple
    path: str
    n_poses: int
    requested: int
    poses: np.ndarray
    status: np.ndarray
    stable: np.ndarray
    deflection_norm: np.ndarray
    rotation_norm: np.ndarray
    k_along: np.ndarray
    k_min: np.ndarray
    wrench: np.ndarray
    gravity: np.ndarray
    loads: tuple = ()

    @property
    def ok(self) -> np.ndarray:
        return self.status == STATUS.index("ok")

    def status_counts(self) -> dict[str, int]:
        return {STATUS[int(c)]: int(n) for c, n in zip(*np.unique(self.status, return_counts=True))}


class CsvStream:
    """Writes the rows of a map to a CSV file as its chunks finish, in pose order, without
    holding the map: a chunk that finishes before an earlier one waits (at most the chunks in
    flight, :data:`~vjm_pin.analysis.map_backends.IN_FLIGHT` per worker), every other chunk is
    written and dropped at once. The file is a temporary one next to ``path`` until
    :meth:`commit` renames it (an interrupted or failed map leaves no half file).

    Attributes:
        held_max: The most chunks ever waiting (for the tests: it does not grow with N).
    """

    def __init__(self, path, names, poses: np.ndarray):
        import tempfile

        self.path = Path(path)
        self.names = list(names)
        self.poses = poses
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.stem}.", suffix=".csv.part", dir=self.path.parent)
        self.tmp = Path(tmp)
        self.fh = os.fdopen(fd, "w", encoding="utf-8", newline="")
        self.writer = csv.writer(self.fh)
        self.writer.writerow(_csv_header(self.names))
        self.next = 0  # first pose not yet written
        self.pending: dict[int, list] = {}
        self.held_max = 0
        n = poses.shape[0]
        self.written = np.zeros(n, dtype=bool)
        self.status = np.zeros(n, dtype=np.uint8)
        self.stable = np.zeros(n, dtype=bool)
        self.mags = np.full((4, n), np.nan)

    def add(self, start: int, rows) -> None:
        """Take the rows of the chunk that starts at pose ``start``."""
        self.pending[start] = rows
        self.held_max = max(self.held_max, len(self.pending))
        while self.next in self.pending:
            rows = self.pending.pop(self.next)
            self._write(self.next, rows)
            self.next += len(rows)

    def _write(self, start: int, rows) -> None:
        r = PoseRows.from_dicts(rows)
        sl = slice(start, start + len(r))
        dns = np.linalg.norm(r.deflection[:, :3], axis=1)  # as MapResult.columns: the same digits
        rns = np.linalg.norm(r.deflection[:, 3:], axis=1)
        if r.text is None:
            r.text = _csv_lines(_csv_floats(self.poses[sl], r), r.stable, np.asarray(STATUS)[r.status])
        self.fh.write(r.text)
        self.written[sl] = True
        self.status[sl] = r.status
        self.stable[sl] = r.stable
        self.mags[:, sl] = (dns, rns, r.k_along, r.k_min)

    def commit(self) -> None:
        """Write the chunks still waiting (after an interrupt: the finished poses, in pose order,
        with gaps), close and rename the file over ``path``."""
        for start in sorted(self.pending):
            self._write(start, self.pending.pop(start))
        self.fh.close()
        try:
            os.chmod(self.tmp, os.stat(self.path).st_mode & 0o7777)
        except FileNotFoundError:
            m = os.umask(0)
            os.umask(m)
            os.chmod(self.tmp, 0o666 & ~m)
        os.replace(self.tmp, self.path)

    def discard(self) -> None:
        import contextlib

        with contextlib.suppress(OSError):
            self.fh.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.tmp)


def stream_map(
    vm: VjmModel,
    names,
    poses: np.ndarray,
    wrench,
    path,
    *,
    gravity=None,
    loads=(),
    method: str = "eq30",
    backend: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    progress=None,
) -> MapSummary:
    """:func:`run_map` written straight to the CSV file ``path`` (:class:`CsvStream`): the same
    rows as ``run_map(...).to_csv(path)``, in bounded memory for maps of millions of poses.

    On Ctrl-C the finished poses are written (pose order) and :class:`MapInterrupted` carries
    their :class:`MapSummary`; on any other error no file is left.

    Raises:
        As :func:`run_map`; InputError: ``path`` does not end in ``.csv``.
    """
    from vjm_pin.exceptions import MapInterrupted

    if Path(path).suffix != ".csv":
        raise InputError(f"a streamed map is written as CSV: the file must end in .csv, got '{Path(path).name}'")
    names, poses, w, g, loads = _check_problem(vm, names, poses, wrench, gravity, loads)
    sink = CsvStream(path, names, poses)
    try:
        _run_chunks(vm, names, poses, w, g, loads, method, backend, workers, scheduler, chunk, sink.add, progress, csv_text=True)
    except KeyboardInterrupt:
        if sink.next or sink.pending:
            sink.commit()  # the finished poses
        else:
            sink.discard()  # nothing finished: an existing file stays as it was
        raise MapInterrupted(_stream_summary(vm, names, sink, w, g, loads), poses.shape[0]) from None
    except BaseException:
        sink.discard()
        raise
    sink.commit()
    return _stream_summary(vm, names, sink, w, g, loads)


def _stream_summary(vm, names, sink: CsvStream, w, g, loads) -> MapSummary:
    m = sink.written
    return MapSummary(
        model=vm.name,
        frame=vm.frame,
        joints=tuple(names),
        path=str(sink.path),
        n_poses=int(m.sum()),
        requested=int(m.size),
        poses=sink.poses if m.all() else sink.poses[m],
        status=sink.status[m],
        stable=sink.stable[m],
        deflection_norm=sink.mags[0, m],
        rotation_norm=sink.mags[1, m],
        k_along=sink.mags[2, m],
        k_min=sink.mags[3, m],
        wrench=w,
        gravity=np.zeros(3) if g is None else g,
        loads=tuple(loads),
    )


def _csv_header(names) -> list[str]:
    return [
        *names,
        "p0_x_m", "p0_y_m", "p0_z_m",
        "dx_m", "dy_m", "dz_m", "rx_rad", "ry_rad", "rz_rad",
        "deflection_m", "rotation_rad", "k_along_N_per_m", "k_min_N_per_m", "stable", "status",
    ]  # fmt: skip


def _csv_floats(poses: np.ndarray, r: PoseRows) -> np.ndarray:
    """(n, k + 17) the float columns of the CSV rows of ``poses`` (n, k) and their results."""
    d = r.deflection
    dns = np.linalg.norm(d[:, :3], axis=1)  # as MapResult.columns: the same digits
    rns = np.linalg.norm(d[:, 3:], axis=1)
    return np.column_stack([poses, r.p0, d, dns, rns, r.k_along, r.k_min])


def _csv_lines(floats: np.ndarray, stable: np.ndarray, status) -> str:
    """CSV text of rows of float columns followed by ``stable`` (0/1) and ``status``: the same
    text as ``csv.writer`` on :func:`_csv_value` of each field (``repr`` of the floats, ``\\r\\n``
    line ends; no field needs quoting), built without a Python call per field."""
    flags = np.where(np.asarray(stable, bool), "1", "0").tolist()
    return "".join(
        f"{','.join(map(repr, f))},{b},{st}\r\n" for f, b, st in zip(floats.tolist(), flags, list(status))
    )


def _check_problem(vm: VjmModel, names, poses, wrench, gravity, loads):
    """(names, poses (N, n), wrench (6,), gravity (3,) or None, loads) checked (:func:`run_map`)."""
    from vjm_pin.exceptions import RoleError

    names = list(names)
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != len(names) or poses.shape[0] < 1:
        raise InputError(
            f"poses must be an (N ≥ 1, {len(names)}) array for joints {names}, got shape {poses.shape}"
        )
    if not np.all(np.isfinite(poses)):
        raise InputError("poses contain NaN or infinite values")
    from vjm_pin.model.task import task_vector

    # 6 numbers, or 3 (a force; the moment zero); components outside the task are checked below
    w = task_vector(wrench, name="wrench", unit="N, N·m", outside_task="keep")
    for n in names:
        vm.joint_index(n)
        if vm.roles[n] == "spring":
            raise RoleError(f"joint '{n}' is a virtual spring joint; a map cannot set its position")
        if vm.closures and vm.roles[n] == "passive":
            raise RoleError(
                f"joint '{n}' is a passive joint of a closed mechanism: it is found by re-assembling the "
                "mechanism at each pose; vary its actuated joints"
            )
    loads = _check_loads(vm, loads)
    g = None if gravity is None else np.asarray(gravity, float).reshape(-1)
    if g is not None and (g.shape != (3,) or not np.all(np.isfinite(g))):
        raise InputError(f"gravity must be 3 finite numbers (m/s²), got {np.asarray(gravity).tolist()}")
    if uses_mechanism_solver(vm, g, loads):
        outside = [c for i, c in enumerate(("x", "y", "z", "rx", "ry", "rz")) if w[i] and i not in vm.task]
        if outside:
            raise InputError(
                f"wrench has components {outside} outside the task ({' '.join(vm.task_names)}) of model "
                f"'{vm.name}'; give them as a dead load at a frame"
            )
    return names, poses, w, g, loads


def _check_workers(workers, chunk, scheduler, n_poses: int, max_chunk: int = 50) -> tuple[int, int]:
    """(workers, chunk) checked, with their defaults (:func:`run_map`)."""
    for what, v in (("workers", workers), ("chunk", chunk)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1):
            raise InputError(f"{what} must be a positive integer, got {v!r}")
    cores = os.cpu_count() or 1
    if workers is not None and workers > MAX_WORKERS_PER_CORE * cores and not scheduler:
        raise InputError(
            f"workers: {workers} processes on {cores} cores is more than "
            f"{MAX_WORKERS_PER_CORE} per core; the map would run slower, not faster"
        )
    workers = int(workers or cores)
    if chunk is None:
        chunk = max(1, min(max_chunk, math.ceil(n_poses / (4 * workers))))
    return workers, int(chunk)


def _check_loads(vm: VjmModel, loads) -> tuple:
    """``loads`` as a tuple of :class:`~vjm_pin.kinematics.dead_loads.Load` at frames of ``vm``.

    Raises:
        InputError: not Load objects. FrameNotFound: an unknown frame (lists the frames).
    """
    from vjm_pin.kinematics.dead_loads import DeadLoads, Load

    if loads is None:
        return ()
    if isinstance(loads, Load):
        loads = (loads,)
    loads = tuple(loads)
    bad = [type(ld).__name__ for ld in loads if not isinstance(ld, Load)]
    if bad:
        raise InputError(f"loads must be Load objects (frame, wrench), got {bad[0]}")
    if loads:
        DeadLoads(vm, loads, None)  # FrameNotFound before any work
    return loads


class _Columns:
    """The per-pose arrays of a map being filled chunk by chunk (private to run_map)."""

    def __init__(self, n: int):
        self.p0 = np.full((n, 3), np.nan)
        self.deflection = np.full((n, 6), np.nan)
        self.k_along = np.full(n, np.nan)
        self.k_min = np.full(n, np.nan)
        self.stable = np.zeros(n, dtype=bool)
        self.status = np.full(n, "", dtype="<U16")

    def fill(self, start: int, rows) -> None:
        r = PoseRows.from_dicts(rows)
        sl = slice(start, start + len(r))
        self.p0[sl] = r.p0
        self.deflection[sl] = r.deflection
        self.k_along[sl] = r.k_along
        self.k_min[sl] = r.k_min
        self.stable[sl] = r.stable
        self.status[sl] = np.asarray(STATUS)[r.status]

    def result(self, vm, names, poses, w, g, mask, loads=()) -> MapResult:
        return MapResult(
            model=vm.name,
            frame=vm.frame,
            joints=tuple(names),
            poses=poses[mask],
            p0=self.p0[mask],
            deflection=self.deflection[mask],
            k_along=self.k_along[mask],
            k_min=self.k_min[mask],
            stable=self.stable[mask],
            status=self.status[mask],
            wrench=w,
            gravity=np.zeros(3) if g is None else g,
            loads=tuple(loads),
        )
