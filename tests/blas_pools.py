"""The BLAS thread pools as threadpoolctl reports them, for the tests of the one-BLAS-thread
policies (vjm_pin/solver/threads.py; the fixture ``two_blas_threads`` in conftest.py)."""

from __future__ import annotations

from threadpoolctl import threadpool_info


def blas_threads() -> list[int]:
    """The thread count of every BLAS pool loaded in this process."""
    return [d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas"]
