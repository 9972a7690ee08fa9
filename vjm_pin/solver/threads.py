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
are affected, not the user's environment or their other numpy work. (``EquilibriumSolver.solve``'s
lean warm-start path skips the limit for models of order ≤ 48, where OpenBLAS runs one thread
anyway: see :mod:`vjm_pin.solver.equilibrium`.)

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
_pairs = None  # (controller, [(thread-count getter, setter)]), see _accessors


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


def _accessors(ctl):
    """(thread-count getter, setter) of each library of ``ctl``, doing what its
    ``threadpoolctl`` controller does: for OpenBLAS the C symbols resolved once (``threadpoolctl``
    looks them up by name at every call: ~2–3 µs against ~0.5 µs, four calls per solve) and, on
    its pthreads layer, the controller's own setter unless this thread already controls the pool
    (its rule: one controlling thread); the controller's own methods for any other library."""
    global _pairs
    if _pairs is None or _pairs[0] is not ctl:
        pairs = []
        for lib in ctl.lib_controllers:
            get, put = lib.get_num_threads, lib.set_num_threads
            if getattr(lib, "internal_api", None) == "openblas":
                try:
                    omp = lib.threading_layer == "openmp"
                    g = lib._get_symbol("omp_get_max_threads" if omp else "openblas_get_num_threads")
                    p = lib._get_symbol("omp_set_num_threads" if omp else "openblas_set_num_threads")
                    shared = type(lib)._SHARED_STATE
                    if g is not None and p is not None and g() == lib.get_num_threads():
                        get = g
                        if omp:
                            put = p
                        else:
                            def put(n, p=p, own=lib.set_num_threads, shared=shared):
                                if shared.controlling_thread is threading.current_thread():
                                    return p(n)
                                return own(n)
                except Exception:  # noqa: BLE001  # pragma: no cover - a threadpoolctl without these internals
                    get, put = lib.get_num_threads, lib.set_num_threads
            pairs.append((get, put))
        _pairs = (ctl, pairs)
    return _pairs[1]


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
                for get, put in _accessors(ctl):
                    n = get()
                    if n != 1:
                        put(1)
                        saved.append((put, n))
            _limiter = saved


def _exit() -> None:
    global _depth, _limiter
    with _lock:
        _depth -= 1
        if _depth == 0 and _limiter is not None:
            for put, n in _limiter:
                put(n)
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
