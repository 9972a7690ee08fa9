"""Compare the Orthoglide loop variant (parallelograms as true loops) with the folded
5-d.o.f.-spring model, at Q0…Q4 (issue 13; ``docs/orthoglide.md``, "Loop variant").

Both models are written by ``scripts/make_orthoglide.py`` with explicit ``<vjm:closure>``
elements (the loop variant as bundled, ``orthoglide-loop-qK``; the folded model with
``platform="closures"``, the same legs as the bundled ``orthoglide-qK``) and solved by one
:class:`~vjm_pin.solver.mechanism.MechanismSolver` each:

- unloaded K_C (:meth:`MechanismSolver.stiffness`): stiffness along the bisector u with the
  platform free across u and free to rotate, ``1/(uᵀ C_tt u)`` (``C = K_C⁻¹``), the same with
  the rotation held (``uᵀ K_tt u``), the largest relative difference of the translational
  compliance block ``C_tt`` and the rotational stiffness ``1/λ_max(C_rr)`` … ``1/λ_min(C_rr)``;
- the critical force along −u (Table 2's direction, legs compressed): a force continuation
  with the platform loaded in all six components (force F·(−u), no moment), each step a
  plain Newton from the previous equilibrium (``follow_stable=False``: the fundamental
  branch is followed), watching the stability margin of the force-controlled mechanism (the
  largest eigenvalue of ``−ZᵀWZ`` on the closure null space, :attr:`MechanismResult.stability`);
  the critical force is where it reaches zero (the platform stiffness K_C stops being
  positive definite), bracketed on a grid and refined by regula falsi (Illinois) to
  :data:`REL_TOL`. The leg force there is ``max_i f_i·F`` (statics,
  ``make_orthoglide.leg_coefficients``).

Usage: ``python scripts/compare_orthoglide_loops.py [--points q0 q1 ...] [--write-doc]``
(about a minute per point; ``--write-doc`` replaces the block between the
``compare_orthoglide_loops`` markers of ``docs/orthoglide.md``).
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vjm_pin.exceptions import NoEquilibrium
from vjm_pin.kinematics.closures import ClosureSet, constraint_rank
from vjm_pin.model.format import load_vjm
from vjm_pin.solver.mechanism import MechanismSolver

ROOT = Path(__file__).resolve().parent.parent
U3 = np.ones(3) / math.sqrt(3)
#: Relative tolerance of the critical force.
REL_TOL = 1e-3
#: Grid of the force continuation, in units of the statics estimate of the critical force
#: (Euler's leg load / max_i f_i): 0 … GRID_END in GRID_STEPS steps.
GRID_END, GRID_STEPS = 1.6, 16
BEGIN = "<!-- BEGIN compare_orthoglide_loops -->"
END = "<!-- END compare_orthoglide_loops -->"


def _generator():
    spec = importlib.util.spec_from_file_location(
        "make_orthoglide", ROOT / "scripts" / "make_orthoglide.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


MO = _generator()


def closed_model(point: str, variant: str):
    """The :class:`VjmModel` of ``variant`` (``loop`` or ``folded``) at ``point``, closures explicit."""
    return load_vjm(MO.orthoglide_urdf(point, variant, platform="closures"))


def closure_rank(vm):
    """:func:`constraint_rank` of the closure Jacobian (columns: the solver's free coordinates θ, q)
    at the reference configuration."""
    cs = ClosureSet(vm)
    jac = cs.evaluate(vm.reference, hessian=False).jacobian
    free = np.concatenate([vm.theta_idx, vm.q_idx]).astype(int)
    return constraint_rank(jac[:, free], cs.labels)


@dataclass(frozen=True)
class Unloaded:
    k_free: float  # N/m, 1/(uᵀ C_tt u)
    k_held: float  # N/m, uᵀ K_tt u
    k_rot: tuple[float, float]  # N·m/rad, smallest and largest rotational stiffness (moments only)
    compliance: np.ndarray  # (6, 6) C = K_C⁻¹


def unloaded(solver: MechanismSolver) -> Unloaded:
    res = solver.solve(wrench=np.zeros(6))
    k = solver.stiffness(res).stiffness
    c = np.linalg.inv(k)
    ev = np.linalg.eigvalsh(0.5 * (c[3:, 3:] + c[3:, 3:].T))
    return Unloaded(
        float(1.0 / (U3 @ c[:3, :3] @ U3)),
        float(U3 @ k[:3, :3] @ U3),
        (1 / ev.max(), 1 / ev.min()),
        c,
    )


def _margin(solver: MechanismSolver, force: float, x0):
    """(margin, result) of the force-controlled equilibrium under F·(−u) from ``x0``; margin =
    largest eigenvalue of −ZᵀWZ (negative: stable). None if Newton fails."""
    w = np.concatenate([-force * U3, np.zeros(3)])
    try:
        res = solver.solve(wrench=w, x0=x0)
    except NoEquilibrium:
        return None, None
    return float(res.stability.eigenvalues.max()), res


def critical_force(solver: MechanismSolver, estimate: float) -> tuple[float, object]:
    """Critical force (N) along −u on the fundamental branch, and the last stable equilibrium
    (module docstring). ``estimate``: the grid scale (N). Raises RuntimeError if the margin
    does not change sign on the grid."""
    x = solver.vm.reference.copy()
    f_lo, m_lo, r_lo = 0.0, None, None
    for f in np.linspace(0.0, GRID_END * estimate, GRID_STEPS + 1)[1:]:
        m, res = _margin(solver, float(f), x)
        if m is None:
            raise RuntimeError(
                f"{solver.vm.name}: no equilibrium at {f:.1f} N on the fundamental branch"
            )
        if m >= 0.0:
            f_hi, m_hi = float(f), m
            break
        f_lo, m_lo, r_lo, x = float(f), m, res, res.x
    else:
        raise RuntimeError(f"{solver.vm.name}: stable up to {GRID_END * estimate:.1f} N")
    if m_lo is None:  # unstable at the first step: bisect from the unloaded margin
        m_lo, r_lo = _margin(solver, 0.0, x)
    side = 0
    while f_hi - f_lo > REL_TOL * f_hi:
        f = f_hi - m_hi * (f_hi - f_lo) / (m_hi - m_lo)
        if not (f_lo < f < f_hi) or side * side > 4:
            f, side = 0.5 * (f_lo + f_hi), 0
        m, res = _margin(solver, f, r_lo.x)
        if m is None or m >= 0.0:
            f_hi, m_hi = f, (m if m is not None else m_hi)
            m_lo = 0.5 * m_lo if side > 0 else m_lo
            side = side + 1 if side >= 0 else 1
        else:
            f_lo, m_lo, r_lo = f, m, res
            m_hi = 0.5 * m_hi if side < 0 else m_hi
            side = side - 1 if side <= 0 else -1
    return 0.5 * (f_lo + f_hi), r_lo


def compare(point: str) -> dict:
    """All numbers of one row of the table."""
    f = MO.leg_coefficients(point, (-1.0, -1.0, -1.0))
    fmax = float(np.max(np.abs(f)))
    estimate = MO.F_CR_TABLE2_Q0 / math.sqrt(3) / fmax
    out = {"point": point, "leg_coefficients": f}
    for variant in ("loop", "folded"):
        vm = closed_model(point, variant)
        info = closure_rank(vm)
        solver = MechanismSolver(vm, follow_stable=False)
        un = unloaded(solver)
        try:
            fcr, _ = critical_force(solver, estimate)
        except RuntimeError as e:
            fcr = float("nan")
            print(f"  {e}", file=sys.stderr)
        out[variant] = {
            "rank": info.rank,
            "rows": len(info.independent) + info.n_redundant,
            "redundant": info.n_redundant,
            "unloaded": un,
            "f_cr": fcr,
            "leg_force": fcr * fmax,
            "n": vm.model.nq,
        }
    cl, cf = out["loop"]["unloaded"].compliance, out["folded"]["unloaded"].compliance
    out["ctt_diff"] = float(np.abs(cl[:3, :3] - cf[:3, :3]).max() / np.abs(cf[:3, :3]).max())
    return out


def table(rows) -> str:
    lines = [
        (
            "Generated by `python scripts/compare_orthoglide_loops.py --write-doc` (folded = the bundled "
            "`orthoglide-qK` legs with explicit platform closures; both solved by `MechanismSolver`)."
        ),
        "",
        (
            "| point | k_u free, loop / folded [kN/mm] | ratio | k_u rotation held, loop / folded "
            "| max rel. diff. of C_tt | rotational stiffness, loop [kN·m/rad] | folded [kN·m/rad] "
            "| F_cr along −u, loop / folded [kN] | ratio | leg force at F_cr, loop / folded [kN] |"
        ),
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        lo, fo = r["loop"], r["folded"]
        ul, uf = lo["unloaded"], fo["unloaded"]
        lines.append(
            f"| {r['point'].upper()} | {ul.k_free / 1e6:.4f} / {uf.k_free / 1e6:.4f} | {ul.k_free / uf.k_free:.5f} "
            f"| {ul.k_held / 1e6:.4f} / {uf.k_held / 1e6:.4f} | {r['ctt_diff']:.1e} "
            f"| {ul.k_rot[0] / 1e3:.2f} … {ul.k_rot[1] / 1e3:.2f} | {uf.k_rot[0] / 1e3:.2f} … {uf.k_rot[1] / 1e3:.2f} "
            f"| {lo['f_cr'] / 1e3:.3f} / {fo['f_cr'] / 1e3:.3f} | {lo['f_cr'] / fo['f_cr']:.3f} "
            f"| {lo['leg_force'] / 1e3:.3f} / {fo['leg_force'] / 1e3:.3f} |"
        )
    lo = rows[0]["loop"]
    fo = rows[0]["folded"]
    lines += [
        "",
        (
            f"Closures of the loop variant: {lo['rows']} rows, rank {lo['rank']}, {lo['redundant']} "
            f"redundant (`constraint_rank`, free coordinates θ, q; {lo['n']} joint coordinates); folded "
            f"with platform closures: {fo['rows']} rows, rank {fo['rank']}, {fo['redundant']} redundant. "
            f"Critical forces to {REL_TOL:g} (relative)."
        ),
    ]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", nargs="+", default=list(MO.POINTS), choices=list(MO.POINTS))
    parser.add_argument(
        "--write-doc", action="store_true", help="write the table into docs/orthoglide.md"
    )
    args = parser.parse_args(argv)
    rows = []
    for p in args.points:
        rows.append(compare(p))
        print(f"{p} done", file=sys.stderr)
    text = table(rows)
    print(text)
    if args.write_doc:
        doc = ROOT / "docs" / "orthoglide.md"
        old = doc.read_text()
        if BEGIN not in old or END not in old:
            print(
                f"compare_orthoglide_loops: error: {doc} has no {BEGIN} … {END} block",
                file=sys.stderr,
            )
            return 2
        head, rest = old.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        doc.write_text(head + BEGIN + "\n" + text + END + tail)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
