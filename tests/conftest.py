"""Suite-wide checks.

Every ``--json`` object a command prints in these tests (through
:func:`vjm_pin.cli.common.dump_json`) is validated against the JSON Schema its command ships
(``vjm_pin/schemas/COMMAND.json``, ``vjm-pin schema COMMAND``): a vocabulary drift fails the
test that produced the output. :data:`JSON_VALIDATED` counts the validated objects by command.
"""

from __future__ import annotations

import collections
import os

import pytest

# The solver's fused Newton kernel (vjm_pin.solver.kernel): its numpy twin for the whole suite, so
# that no test's results depend on how many iterations earlier tests ran ("auto" switches to the
# compiled kernel after JIT_AFTER_ITERATIONS; the two agree to rounding, not bit for bit).
# tests/test_kernel.py selects the compiled kernel explicitly.
os.environ.setdefault("VJM_PIN_JIT", "0")

JSON_VALIDATED: collections.Counter = collections.Counter()


@pytest.fixture(autouse=True)
def _validate_json_outputs(monkeypatch):
    import jsonschema

    from vjm_pin.cli import common
    from vjm_pin.cli.schema import SCHEMAS, load_schema

    original = common.dump_json

    def checked(obj) -> str:
        text = original(obj)
        data = common.to_jsonable(obj)
        command = data.get("command") if isinstance(data, dict) else None
        if command in SCHEMAS:
            jsonschema.validate(data, load_schema(command), cls=jsonschema.Draft202012Validator)
            JSON_VALIDATED[command] += 1
        return text

    monkeypatch.setattr(common, "dump_json", checked)
    yield


@pytest.fixture
def two_blas_threads():
    """Every BLAS pool (numpy's and scipy's OpenBLAS, both loaded as in the solver) limited to 2
    threads for the test (precondition checked), restored after it."""
    import scipy.linalg  # noqa: F401  (both OpenBLAS pools loaded)
    from threadpoolctl import threadpool_limits

    from tests.blas_pools import blas_threads

    with threadpool_limits(limits=2, user_api="blas"):
        outer = blas_threads()
        assert outer and all(n == 2 for n in outer), f"precondition: BLAS pools at 2 threads, got {outer}"
        yield
