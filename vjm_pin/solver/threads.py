"""One BLAS thread inside the solver (issue 14).

The solver's matrices are small (order ≤ a few hundred) and it calls both ``numpy.linalg``
and ``scipy.linalg``, which load separate OpenBLAS libraries, each with its own thread
pool. Above order ~48 OpenBLAS goes multi-threaded and, when the cores are busy (other
processes, or a map's own workers, one per core), the two pools spin against each other: the
k = 8 subdivided column's curve took ~12× longer than under one thread on a loaded 2-core
machine (on an idle one, one thread costs ~15 %; docs/performance.md). The public entry points (``EquilibriumSolver.solve`` /
``solve_wrench`` / ``solve_mixed`` / ``verify``, ``trace_curve``, ``loaded_stiffness``, the
map worker) are therefore wrapped by :func:`one_blas_thread`: both pools are limited to one
thread for the duration of the call and restored afterwards. Only the library's own calls
are affected, not the user's environment or their other numpy work.

The limit is taken once per outermost public call (each library's ``set_num_threads`` through
a cached ``threadpoolctl.ThreadpoolController``, restored on exit); nested calls (``solve_wrench`` → ``solve_mixed`` →
``solve``, a curve's many solves, a map chunk's poses) only count. The count is
process-wide under a lock because a BLAS library's thread count is process-wide.
"""

from __future__ import annotations

import functools
import threading

#: Private switch (False: the old behaviour, BLAS pools as the environment sets them; for the
#: side-by-side benchmark).
_enabled = True

_lock = threading.Lock()
_depth = 0
_limiter = None
_controller = None


def _blas_controller():
    """The cached controller of the BLAS libraries loaded now (numpy's and scipy's), or None
    when ``threadpoolctl`` cannot inspect them."""
    global _controller
    if _controller is None:
        try:
            from threadpoolctl import ThreadpoolController

            from vjm_pin.solver.lapack import lapack

            lapack.load()  # scipy's LAPACK (and its BLAS) first: the controller sees both pools

            _controller = ThreadpoolController().select(user_api="blas")
        except Exception:  # pragma: no cover - an exotic BLAS: run as the environment says
            _controller = False
    return _controller or None


def _enter() -> None:
    global _depth, _limiter
    with _lock:
        _depth += 1
        if _depth == 1:
            ctl = _blas_controller()
            # each library's thread count set directly (ThreadpoolController.limit builds info
            # dicts at every call: twice the cost); restored by _exit
            saved = []
            if ctl is not None:
                for lib in ctl.lib_controllers:
                    n = lib.num_threads
                    if n != 1:
                        lib.set_num_threads(1)
                        saved.append((lib, n))
            _limiter = saved


def _exit() -> None:
    global _depth, _limiter
    with _lock:
        _depth -= 1
        if _depth == 0 and _limiter is not None:
            for lib, n in _limiter:
                lib.set_num_threads(n)
            _limiter = None


class single_blas_thread:
    """Context manager: both BLAS pools at one thread inside, restored on the outermost exit
    (re-entrant, thread-safe; a no-op when the private switch ``_enabled`` is off)."""

    __slots__ = ("_on",)

    def __enter__(self):
        self._on = _enabled
        if self._on:
            _enter()
        return self

    def __exit__(self, *exc):
        if self._on:
            _exit()
        return False


def one_blas_thread(fn):
    """Decorator: run ``fn`` inside :class:`single_blas_thread`."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        if not _enabled:
            return fn(*args, **kwargs)
        _enter()
        try:
            return fn(*args, **kwargs)
        finally:
            _exit()

    return wrapper
