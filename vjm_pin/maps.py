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
``k_min``             smallest eigenvalue of the symmetric part of the translational block
                      of ``K_C`` (N/m): the weakest direction when rotations are held.
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

from .exceptions import InputError
from .model import VjmModel

STATUS = ("ok", "singular", "no-equilibrium")
BACKENDS = ("serial", "local", "dask")


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


def sample_poses(vm: VjmModel, n: int, seed: int = 0, names=None) -> tuple[list[str], np.ndarray]:
    """``n`` poses drawn uniformly within the joint limits (seeded: reproducible)."""
    if int(n) < 1:
        raise InputError(f"--samples must be a positive integer, got {n}")
    names = list(names or mapped_joints(vm))
    if not names:
        raise InputError(
            f"model '{vm.name}' has no actuated joint with an actuator spring to sample; "
            "give the joints to vary with --grid NAME=LO:HI:N"
        )
    lim = joint_limits(vm, names)
    rng = np.random.default_rng(seed)
    return names, lim[:, 0] + rng.random((int(n), len(names))) * (lim[:, 1] - lim[:, 0])


def parse_grid(items) -> dict[str, np.ndarray]:
    """``["NAME=LO:HI:N", ...]`` → {name: values}; :class:`InputError` on bad items."""
    out = {}
    for it in items or []:
        try:
            name, rng_ = it.split("=", 1)
            lo, hi, n = rng_.split(":")
            lo_f, hi_f, n_i = float(lo), float(hi), int(n)
        except ValueError:
            raise InputError(f"--grid expects NAME=LO:HI:N, got '{it}'") from None
        if n_i < 1 or not (math.isfinite(lo_f) and math.isfinite(hi_f)):
            raise InputError(f"--grid {name}: need finite bounds and N ≥ 1, got '{rng_}'")
        out[name] = np.linspace(lo_f, hi_f, n_i)
    return out


def grid_poses(vm: VjmModel, grid: dict) -> tuple[list[str], np.ndarray]:
    """Cartesian product of the grid values; the other joints stay at the reference pose."""
    for n in grid:
        vm.joint_index(n)  # JointNotFound on an unknown name
    names = list(grid)
    return names, np.array(list(itertools.product(*[grid[n] for n in names])), dtype=float)


# ----------------------------------------------------------------------------- one pose
_MODEL_CACHE: dict = {}


def _model_from_text(text: str) -> VjmModel:
    key = hash(text)
    vm = _MODEL_CACHE.get(key)
    if vm is None or vm.urdf != text:
        from .model import load_vjm

        vm = load_vjm(text)
        _MODEL_CACHE.clear()
        _MODEL_CACHE[key] = vm
    return vm


def evaluate_pose(vm: VjmModel, names, values, wrench, gravity=None, method: str = "eq30") -> dict:
    """Deflection and stiffness indices of ``vm`` at the pose ``names = values`` under the
    end ``wrench`` (6,) and, if ``gravity`` (3,) is given, the link weights. Never raises
    for a pose that cannot be analysed: ``status`` says why."""
    from .exceptions import NoEquilibrium, SingularStiffness
    from .kinematics import Kinematics
    from .solver import EquilibriumSolver, loaded_stiffness

    v = vm.with_positions(dict(zip(names, (float(x) for x in values))))
    p0, _ = Kinematics(v.model, v.frame_id).placement(v.reference)
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
            from .loads import LinkLoads, solve_loaded

            loads = None if gravity is None else LinkLoads(np.asarray(gravity, float))
            eq = solve_loaded(v, w, loads, method=method)
            if eq.stiffness is None:
                raise SingularStiffness("singular loaded stiffness")
            k, defl, stable = eq.stiffness.stiffness, eq.deflection, eq.stable
        elif gravity is not None and np.any(np.asarray(gravity) != 0):
            from .loads import LoadError

            raise LoadError(
                f"model '{v.name}' has passive joints: gravity maps need spring and motor joints only"
            )
        else:
            res = EquilibriumSolver(v).solve_wrench(w)
            k, defl, stable = loaded_stiffness(v, res, method).stiffness, res.deflection, res.stable
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
        return math.nan, math.nan
    f = np.asarray(wrench, float)[[t[i] for i in tt]]
    nf = np.linalg.norm(f)
    k_along = math.nan
    if nf > 0:
        fh = f / nf
        k_along = float(1.0 / (fh @ c[np.ix_(tt, tt)] @ fh))
    blk = kt[np.ix_(tt, tt)]
    k_min = float(np.linalg.eigvalsh(0.5 * (blk + blk.T))[0])
    return k_along, k_min


def _chunk_worker(text, names, chunk, wrench, gravity, method):
    """Evaluate a chunk of poses (runs in a worker process)."""
    vm = _model_from_text(text)
    return [evaluate_pose(vm, names, row, wrench, gravity, method) for row in chunk]


# ----------------------------------------------------------------------------- result
@dataclass(frozen=True)
class MapResult:
    """A workspace map.

    Attributes:
        model: Model name. frame: End frame. joints: The varied joint names.
        poses: (N, n) joint values (rad, m).
        p0: (N, 3) unloaded end position (m, world).
        deflection: (N, 6) end deflection (m, rad; world); NaN where ``status`` is not ok.
        k_along: (N,) stiffness along the force (N/m). k_min: (N,) smallest translational
            eigenvalue of K_C (N/m).
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
        cols["deflection_mm"] = np.linalg.norm(self.deflection[:, :3], axis=1) * 1e3
        cols["rotation_mrad"] = np.linalg.norm(self.deflection[:, 3:], axis=1) * 1e3
        cols["k_along_N_per_m"] = self.k_along
        cols["k_min_N_per_m"] = self.k_min
        cols["stable"] = self.stable
        cols["status"] = self.status
        return cols

    def to_csv(self, path) -> None:
        cols = self.columns()
        with open(path, "w", newline="") as fh:
            wr = csv.writer(fh)
            wr.writerow(list(cols))
            for i in range(self.poses.shape[0]):
                wr.writerow([_csv_value(c[i]) for c in cols.values()])

    def to_npz(self, path) -> None:
        np.savez(
            path,
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
        """CSV or NPZ by the file suffix."""
        p = Path(path)
        if p.suffix == ".csv":
            self.to_csv(p)
        elif p.suffix == ".npz":
            self.to_npz(p)
        else:
            raise InputError(f"output file must end in .csv or .npz, got '{p.name}'")

    def plot(self, path) -> None:
        """Scatter of the unloaded end positions (top and side views) coloured by the
        deflection (mm); failed poses as grey crosses. PNG/PDF/SVG by suffix."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        ok = self.ok
        d = np.linalg.norm(self.deflection[:, :3], axis=1) * 1e3
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), constrained_layout=True)
        sc = None
        for ax, (i, j, lab) in zip(axes, ((0, 1, ("x (m)", "y (m)")), (0, 2, ("x (m)", "z (m)")))):
            if ok.any():
                sc = ax.scatter(self.p0[ok, i], self.p0[ok, j], c=d[ok], s=10, cmap="viridis")
            if (~ok).any():
                ax.scatter(
                    self.p0[~ok, i], self.p0[~ok, j], marker="x", c="0.6", s=12, label="no result"
                )
                ax.legend(loc="best")
            ax.set_xlabel(lab[0])
            ax.set_ylabel(lab[1])
            ax.set_aspect("equal", adjustable="datalim")
        if sc is not None:
            fig.colorbar(sc, ax=axes, label="deflection (mm)")
        w = self.wrench
        fig.suptitle(f"{self.model}: end '{self.frame}', wrench {np.round(w, 3).tolist()} N, N·m")
        fig.savefig(path, dpi=110)
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
            cores) or ``"dask"`` (``dask.distributed`` client on ``scheduler``; a local
            cluster of ``workers`` processes when None).
        chunk: Poses per task (default: about 4 tasks per worker, at most 50 poses).
        progress: Called with the number of poses done after each chunk.
    """
    if backend not in BACKENDS:
        raise InputError(f"unknown backend '{backend}'; choose one of {BACKENDS}")
    poses = np.asarray(poses, dtype=float).reshape(-1, len(names))
    if not np.all(np.isfinite(poses)):
        raise InputError("poses contain NaN or infinite values")
    w = np.asarray(wrench, float).reshape(-1)
    if w.size == 3:
        w = np.concatenate([w, np.zeros(3)])
    if w.shape != (6,) or not np.all(np.isfinite(w)):
        raise InputError(f"wrench must be 3 or 6 finite numbers, got {np.asarray(wrench).tolist()}")
    for n in names:
        vm.joint_index(n)
    if gravity is not None and vm.n_q:
        from .loads import LoadError

        raise LoadError(
            f"model '{vm.name}' has passive joints {vm.q_names}: gravity maps need spring and motor joints only"
        )
    g = None if gravity is None else np.asarray(gravity, float)
    n_poses = poses.shape[0]
    workers = int(workers or os.cpu_count() or 1)
    if chunk is None:
        chunk = max(1, min(50, math.ceil(n_poses / (4 * workers))))
    chunks = [poses[i : i + chunk] for i in range(0, n_poses, chunk)]
    text = vm.urdf
    args = (text, list(names))
    results: list = [None] * len(chunks)
    done = 0

    def report(k, rows):
        nonlocal done
        results[k] = rows
        done += len(rows)
        if progress is not None:
            progress(done)

    if backend == "serial" or (backend == "local" and workers == 1):
        for k, c in enumerate(chunks):
            report(k, _chunk_worker(*args, c, w, g, method))
    elif backend == "local":
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=workers) as ex:
            futs = {
                ex.submit(_chunk_worker, *args, c, w, g, method): k for k, c in enumerate(chunks)
            }
            for f in as_completed(futs):
                report(futs[f], f.result())
    else:
        _run_dask(args, chunks, w, g, method, workers, scheduler, report)
    rows = [r for rs in results for r in rs]
    return MapResult(
        model=vm.name,
        frame=vm.frame,
        joints=tuple(names),
        poses=poses,
        p0=np.array([r["p0"] for r in rows]).reshape(-1, 3),
        deflection=np.array([r["deflection"] for r in rows]).reshape(-1, 6),
        k_along=np.array([r["k_along"] for r in rows], dtype=float),
        k_min=np.array([r["k_min"] for r in rows], dtype=float),
        stable=np.array([r["stable"] for r in rows], dtype=bool),
        status=np.array([r["status"] for r in rows], dtype="<U16"),
        wrench=w,
        gravity=np.zeros(3) if g is None else g,
    )


def _run_dask(args, chunks, w, g, method, workers, scheduler, report):
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as e:  # pragma: no cover - the test extra installs it
        raise InputError(f"the dask backend needs 'dask[distributed]' ({e})") from None
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as e:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
    else:
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
        )
        client = Client(cluster)
    try:
        futs = [client.submit(_chunk_worker, *args, c, w, g, method, pure=False) for c in chunks]
        index = {f.key: k for k, f in enumerate(futs)}
        for f in as_completed(futs):
            report(index[f.key], f.result())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
