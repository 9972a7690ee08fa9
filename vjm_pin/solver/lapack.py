"""scipy's LAPACK routines without importing ``scipy.linalg`` (issue 14: import time).

The solver calls a few LAPACK routines directly (QR, triangular solves, SVD, symmetric
eigenvalues, Cholesky, LU): at the small orders of VJM models ``numpy.linalg``'s wrappers cost
more than the factorisations. ``from scipy.linalg import lapack`` executes the whole
``scipy.linalg`` package (with its array-API layer: numpy.f2py, numpy.ma, numpy.testing, …),
which costs more than importing Pinocchio itself and would dominate a one-shot ``vjm-pin
analyze``. The routines live in one compiled module, ``scipy.linalg._flapack``, that depends on
numpy only: :data:`lapack` loads that module alone, on first use, and registers it under its
own name so that a later ``import scipy.linalg`` reuses the very same module (and functions:
results are bit for bit those of ``scipy.linalg.lapack``, ``tests/test_screw.py`` checks the
identity). If ``scipy.linalg`` is already imported, or the module cannot be located, it is
``scipy.linalg.lapack`` itself.

:func:`solve_triangular` is ``scipy.linalg.solve_triangular`` for 2-D float arrays (the same
``trtrs`` call, the same errors), without importing ``scipy.linalg``.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import sys

import numpy as np

_NAME = "scipy.linalg._flapack"


def _load_flapack():
    """The module ``scipy.linalg._flapack``, loaded without executing ``scipy.linalg``."""
    if "scipy.linalg" in sys.modules or _NAME in sys.modules:
        from scipy.linalg import lapack as full  # already paid for: the public module

        return full
    try:
        spec = importlib.util.find_spec("scipy")  # locates the package without importing it
        for base in spec.submodule_search_locations or ():
            for suffix in importlib.machinery.EXTENSION_SUFFIXES:
                path = f"{base}/linalg/_flapack{suffix}"
                try:
                    loader = importlib.machinery.ExtensionFileLoader(_NAME, path)
                    sub = importlib.util.spec_from_file_location(_NAME, path, loader=loader)
                    if sub is None:
                        continue
                    mod = importlib.util.module_from_spec(sub)
                except (ImportError, OSError):
                    continue
                sub.loader.exec_module(mod)
                sys.modules[_NAME] = mod  # ``import scipy.linalg`` later reuses it
                return mod
    except Exception:  # noqa: BLE001, S110 - an unusual scipy layout: the public module below
        pass
    from scipy.linalg import lapack as full

    return full


class _Lazy:
    """Attribute access loads the LAPACK module once (see the module docstring); each routine
    is then kept as an instance attribute (later look-ups do not reach ``__getattr__``)."""

    def __init__(self):
        self._mod = None

    def __getattr__(self, name):
        fn = getattr(self.load(), name)
        if not name.startswith("_"):
            self.__dict__[name] = fn
        return fn

    def load(self):
        """The LAPACK module (loaded on the first call)."""
        mod = self._mod
        if mod is None:
            mod = self._mod = _load_flapack()
        return mod


#: scipy's LAPACK routines (``lapack.dgeqrf`` …), loaded on first use.
lapack = _Lazy()


def solve_triangular(a, b, trans=0, lower: bool = False):
    """``scipy.linalg.solve_triangular(a, b, trans, lower)`` for float arrays: the same
    LAPACK ``trtrs`` call, ``ValueError`` for NaN/inf input, ``numpy.linalg.LinAlgError`` for
    a singular triangle."""
    trans = {"N": 0, "T": 1, "C": 2}.get(trans, trans)
    a1 = np.asarray_chkfinite(a)
    b1 = np.asarray_chkfinite(b)
    if a1.ndim != 2 or a1.shape[0] != a1.shape[1]:
        raise ValueError("expected square matrix")
    if a1.shape[0] != b1.shape[0]:
        raise ValueError(f"shapes of a {a1.shape} and b {b1.shape} are incompatible")
    if b1.size == 0:
        return np.empty_like(b1, dtype=float)
    trtrs = lapack.dtrtrs
    if a1.flags.f_contiguous or trans == 2:
        x, info = trtrs(a1, b1, overwrite_b=0, lower=lower, trans=trans)
    else:  # trtrs expects Fortran order: solve the transposed system (as scipy)
        x, info = trtrs(a1.T, b1, overwrite_b=0, lower=not lower, trans=not trans)
    if info == 0:
        return x
    if info > 0:
        raise np.linalg.LinAlgError(f"singular matrix: resolution failed at diagonal {info - 1}")
    raise ValueError(f"illegal value in {-info}-th argument of internal trtrs")
