"""Workspace maps: deflection and stiffness indices over many poses, on local cores or Dask.

Every pose is evaluated by the same pure function (:func:`evaluate_pose`) from the model's
URDF text, the joint values, the wrench and the options, so the results do not depend on
the backend, the number of workers or the chunking: ``serial``, ``local`` (a process pool
on all cores) and ``dask`` (``dask.distributed``; a local cluster when no scheduler
address is given) agree bit for bit (``tests/test_maps.py``).

Indices at each pose (the end wrench ``F`` of eq. 11 and, optionally, link loads of
:mod:`vjm_pin.loads`):

``deflection``        (6,) end displacement (m, rad), world axes.
``k_along``           translational stiffness along the force direction ``f̂`` (N/m):
                      ``1 / (f̂ᵀ C_tt f̂)`` with ``C = K_C⁻¹`` the loaded compliance (eq. 30);
                      rotations are free, so it is the stiffness the force really meets.
``k_min``             weakest translational stiffness, the end free to rotate (N/m):
                      ``1 / λ_max(sym C_tt)`` (:func:`vjm_pin.analysis.indices.weakest_translation`;
                      0 where K_C is singular along a translation).
``stable``            verdict of eq. (23) at the loaded equilibrium.
``status``            ``ok``, ``singular`` (no finite stiffness there, e.g. a singular pose)
                      or ``no-equilibrium`` (the load exceeds what the pose can carry).
"""

from __future__ import annotations

import csv
import itertools
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import InputError
from vjm_pin.model.format import VjmModel

STATUS = ("ok", "singular", "no-equilibrium")
BACKENDS = ("serial", "local", "dask")
#: Most poses one map may hold (about 100 bytes each in memory and 300 in a CSV file).
MAX_POSES = 10_000_000
#: Most local worker processes per core (more only adds memory and start-up time).
MAX_WORKERS_PER_CORE = 16


# ----------------------------------------------------------------------------- poses
def mapped_joints(vm: VjmModel) -> list[str]:
    """The joints a map varies: the actuated joints with an actuator spring (the robot's
    motors), in configuration order."""
    act = {g.joints[0] for g in vm.springs if g.link is None and len(g.joints) == 1}
    return [n for n in vm.joint_names if n in act]


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
        raise InputError(f"--samples must be a positive integer, got {n!r}")
    _check_count(int(n), "--samples")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"--seed must be an integer ≥ 0, got {seed!r}")
    names = list(names or mapped_joints(vm))
    if not names:
        raise InputError(
            f"model '{vm.name}' has no actuated joint with an actuator spring to sample; "
            "give the joints to vary with --grid NAME=LO:HI:N"
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
            raise InputError(f"--grid expects NAME=LO:HI:N (N an integer), got '{it}'") from None
        if not name:
            raise InputError(f"--grid '{it}': no joint name before '='")
        if name in out:
            raise InputError(f"--grid: joint '{name}' given twice")
        if n_i < 1 or not (math.isfinite(lo_f) and math.isfinite(hi_f)):
            raise InputError(f"--grid {name}: need finite bounds and N ≥ 1, got '{rng_}'")
        if lo_f > hi_f:
            raise InputError(f"--grid {name}: LO {lo_f:g} is above HI {hi_f:g}")
        if lo_f == hi_f and n_i > 1:
            raise InputError(
                f"--grid {name}: LO = HI = {lo_f:g} gives {n_i} equal values; use N = 1"
            )
        total *= n_i
        _check_count(total, "--grid")
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
        raise InputError("--grid: no joint given (NAME=LO:HI:N ...)")
    total = 1
    for n, vals in grid.items():
        vm.joint_index(n)  # JointNotFound on an unknown name
        if vm.roles[n] == "spring":
            raise RoleError(
                f"--grid {n}: a virtual spring joint cannot be set (its position is its rest value)"
            )
        vals = np.asarray(vals, dtype=float).reshape(-1)
        lim = _urdf_limits(vm, n)
        if lim is not None and (vals.min() < lim[0] or vals.max() > lim[1]):
            raise InputError(
                f"--grid {n}: values {vals.min():g} … {vals.max():g} leave the joint limits "
                f"[{lim[0]:g}, {lim[1]:g}] of the URDF"
            )
        total *= vals.size
    _check_count(total, "--grid")
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


def _shared_kinematics(model, frame_id: int):
    from vjm_pin.kinematics.chain import Kinematics

    key = (id(model), int(frame_id))
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


def evaluate_pose(vm: VjmModel, names, values, wrench, gravity=None, method: str = "eq30") -> dict:
    """Deflection and stiffness indices of ``vm`` at the pose ``names = values`` under the
    end ``wrench`` (6,) and, if ``gravity`` (3,) is given, the link weights. Never raises
    for a pose that cannot be analysed: ``status`` says why."""
    from vjm_pin.solver.threads import single_blas_thread

    with single_blas_thread():  # one BLAS thread inside (vjm_pin.solver.threads)
        return _evaluate_pose(vm, names, values, wrench, gravity, method)


def _evaluate_pose(vm: VjmModel, names, values, wrench, gravity, method) -> dict:
    from vjm_pin.exceptions import NoEquilibrium, SingularStiffness
    from vjm_pin.solver import EquilibriumSolver, loaded_stiffness

    v = vm.with_positions(dict(zip(names, (float(x) for x in values))))
    kin = _shared_kinematics(v.model, v.frame_id)
    p0, _ = kin.placement(v.reference)
    row = {
        "p0": p0,
        "deflection": np.full(6, np.nan),
        "k_along": np.nan,
        "k_min": np.nan,
        "stable": False,
        "status": "ok",
    }
    w = np.asarray(wrench, float)
    try:
        if v.n_q == 0:  # springs and motors only: Newton on eq. (5') (vjm_pin.loads)
            from vjm_pin.loads import LinkLoads, solve_loaded

            loads = None if gravity is None else LinkLoads(np.asarray(gravity, float))
            eq = solve_loaded(v, w, loads, method=method, kin=kin)
            if eq.stiffness is None:
                raise SingularStiffness("singular loaded stiffness")
            k, defl, stable = eq.stiffness.stiffness, eq.deflection, eq.stable
        elif gravity is not None and np.any(np.asarray(gravity) != 0):
            from vjm_pin.loads import LoadError

            raise LoadError(
                f"model '{v.name}' has passive joints: gravity maps need spring and motor joints only"
            )
        else:
            res = EquilibriumSolver(v, _kin=kin).solve_wrench(w)
            k, defl, stable = loaded_stiffness(v, res, method, kin=kin).stiffness, res.deflection, res.stable
    except SingularStiffness:
        row["status"] = "singular"
        return row
    except NoEquilibrium:
        row["status"] = "no-equilibrium"
        return row
    row["deflection"] = defl
    row["stable"] = bool(stable)
    row["k_along"], row["k_min"] = stiffness_indices(k, w, v.task)
    return row


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


def _chunk_worker(text, names, wrench, gravity, method, chunk):
    """Evaluate a chunk of poses (runs in a worker process)."""
    from vjm_pin.exceptions import VjmError
    from vjm_pin.solver.threads import single_blas_thread

    vm = _model_from_text(text)
    try:
        with single_blas_thread():  # once per chunk, not per pose
            return [evaluate_pose(vm, names, row, wrench, gravity, method) for row in chunk]
    except VjmError as e:  # subclasses with extra constructor arguments do not unpickle
        raise VjmError(str(e)) from None


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
        with atomic_output(path, "w") as fh:
            wr = csv.writer(fh)
            wr.writerow(list(cols))
            for i in range(self.poses.shape[0]):
                wr.writerow([_csv_value(c[i]) for c in cols.values()])

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

    def plot(self, path) -> None:
        """Scatter of the unloaded end positions (top and side views) coloured by the
        deflection (mm); failed poses as grey crosses. PNG/PDF/SVG by suffix; written
        atomically."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from vjm_pin.outputs import atomic_output

        ok = self.ok
        d = np.linalg.norm(self.deflection[:, :3], axis=1) * 1e3
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), constrained_layout=True)
        try:
            sc = None
            for ax, (i, j, lab) in zip(
                axes, ((0, 1, ("x (m)", "y (m)")), (0, 2, ("x (m)", "z (m)")))
            ):
                if ok.any():
                    sc = ax.scatter(self.p0[ok, i], self.p0[ok, j], c=d[ok], s=10, cmap="viridis")
                if (~ok).any():
                    ax.scatter(
                        self.p0[~ok, i],
                        self.p0[~ok, j],
                        marker="x",
                        c="0.6",
                        s=12,
                        label="no result",
                    )
                    ax.legend(loc="best")
                ax.set_xlabel(lab[0])
                ax.set_ylabel(lab[1])
                ax.set_aspect("equal", adjustable="datalim")
            if sc is not None:
                fig.colorbar(sc, ax=axes, label="deflection (mm)")
            w = self.wrench
            fig.suptitle(
                f"{self.model}: end '{self.frame}', wrench {np.round(w, 3).tolist()} N, N·m"
            )
            with atomic_output(path) as tmp:
                fig.savefig(tmp, dpi=110)
        finally:
            plt.close(fig)


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
    method: str = "eq30",
    backend: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    chunk: int | None = None,
    progress=None,
) -> MapResult:
    """Evaluate the map over ``poses`` (N, len(names)).

    Args:
        backend: ``"serial"``, ``"local"`` (process pool, ``workers`` processes, default all
            cores) or ``"dask"`` (``dask.distributed`` client on ``scheduler``, an address
            ``tcp://HOST:PORT``; a local cluster of ``workers`` processes when None).
        chunk: Poses per task (default: about 4 tasks per worker, at most 50 poses).
        progress: Called with the number of poses done after each chunk.

    Raises:
        InputError: bad poses, wrench, backend, workers or chunk. SchedulerError (an
            InputError): no Dask scheduler at ``scheduler``. MapInterrupted: Ctrl-C; it carries the
            poses finished so far (:mod:`vjm_pin.analysis.map_backends` stops the workers first).
    """
    from vjm_pin.exceptions import MapInterrupted, RoleError
    from vjm_pin.analysis.map_backends import run_chunks

    if backend not in BACKENDS:
        raise InputError(f"unknown backend '{backend}'; choose one of {BACKENDS}")
    names = list(names)
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != len(names) or poses.shape[0] < 1:
        raise InputError(
            f"poses must be an (N ≥ 1, {len(names)}) array for joints {names}, got shape {poses.shape}"
        )
    if not np.all(np.isfinite(poses)):
        raise InputError("poses contain NaN or infinite values")
    w = np.asarray(wrench, float).reshape(-1)
    if w.size == 3:
        w = np.concatenate([w, np.zeros(3)])
    if w.shape != (6,) or not np.all(np.isfinite(w)):
        raise InputError(f"wrench must be 3 or 6 finite numbers, got {np.asarray(wrench).tolist()}")
    for n in names:
        vm.joint_index(n)
        if vm.roles[n] == "spring":
            raise RoleError(f"joint '{n}' is a virtual spring joint; a map cannot set its position")
    if gravity is not None and vm.n_q:
        from vjm_pin.loads import LoadError

        raise LoadError(
            f"model '{vm.name}' has passive joints {vm.q_names}: gravity maps need spring and motor joints only"
        )
    for what, v in (("workers", workers), ("chunk", chunk)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1):
            raise InputError(f"{what} must be a positive integer, got {v!r}")
    g = None if gravity is None else np.asarray(gravity, float)
    n_poses = poses.shape[0]
    cores = os.cpu_count() or 1
    if workers is not None and workers > MAX_WORKERS_PER_CORE * cores and not scheduler:
        raise InputError(
            f"workers: {workers} processes on {cores} cores is more than "
            f"{MAX_WORKERS_PER_CORE} per core; the map would run slower, not faster"
        )
    workers = int(workers or cores)
    if chunk is None:
        chunk = max(1, min(50, math.ceil(n_poses / (4 * workers))))
    starts = list(range(0, n_poses, chunk))
    out = _Columns(n_poses)
    finished = np.zeros(len(starts), dtype=bool)
    done = 0

    def report(k, rows):
        nonlocal done
        out.fill(starts[k], rows)
        finished[k] = True  # only now: a chunk cut short by Ctrl-C is not counted
        done += len(rows)
        if progress is not None:
            progress(done)

    try:
        run_chunks(
            _chunk_worker,
            (vm.urdf, names, w, g, method),
            [poses[i : i + chunk] for i in starts],
            report,
            backend=backend,
            workers=workers,
            scheduler=scheduler,
        )
    except KeyboardInterrupt:
        mask = np.zeros(n_poses, dtype=bool)
        for k in np.flatnonzero(finished):
            mask[starts[k] : starts[k] + chunk] = True
        raise MapInterrupted(out.result(vm, names, poses, w, g, mask), n_poses) from None
    return out.result(vm, names, poses, w, g, np.ones(n_poses, dtype=bool))


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
        for i, r in enumerate(rows, start):
            self.p0[i] = r["p0"]
            self.deflection[i] = r["deflection"]
            self.k_along[i] = r["k_along"]
            self.k_min[i] = r["k_min"]
            self.stable[i] = r["stable"]
            self.status[i] = r["status"]

    def result(self, vm, names, poses, w, g, mask) -> MapResult:
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
        )
