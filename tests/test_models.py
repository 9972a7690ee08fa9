"""Drift test: the bundled paper models are generated, never hand-edited (STYLE 7)."""

from __future__ import annotations

import importlib.util
import math
import re
from pathlib import Path

import numpy as np
import pytest

from vjm_pin.model.format import load_vjm
from vjm_pin.model.paper_models import PAPER_BEAM, PAPER_KTHETA_FACTOR

from .urdf_compare import urdf_differences

ROOT = Path(__file__).resolve().parent.parent


def _paper_models():
    spec = importlib.util.spec_from_file_location(
        "make_paper_models", ROOT / "scripts" / "make_paper_models.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.paper_models()


def test_committed_models_match_the_generator():
    generated = _paper_models()
    assert len(generated) == 9
    for name, text in generated.items():
        path = ROOT / "models" / "urdf" / name
        assert path.is_file(), f"{name} missing: run scripts/make_paper_models.py"
        assert not urdf_differences(path.read_text(), text), (
            f"{name} differs from the generator (rtol 1e-12): {urdf_differences(path.read_text(), text)}; "
            "run scripts/make_paper_models.py"
        )


def test_ktheta_factor_is_the_root_of_the_buckling_polynomial():
    """Closed form of the three-link tip-spring chain: p² + 6p − 12 = 0 (report)."""
    p = PAPER_KTHETA_FACTOR
    assert abs(p * p + 6 * p - 12) < 1e-12


@pytest.mark.parametrize("name", ["paper-b-s", "paper-c-pi"])
def test_beam_parameters_kept_in_si(name):
    """E, ν, L, a, b stay explicit so results can be read in SI; Kθ = (√21−3)·E·I_z/L = 1 N·m/rad."""
    vm = load_vjm(ROOT / "models" / "urdf" / f"{name}.urdf")
    for g in vm.springs:
        b = g.beam
        assert b is not None
        assert b["a"] == pytest.approx(PAPER_BEAM["a"]) and b["b"] == pytest.approx(PAPER_BEAM["b"])
        assert b["length"] == pytest.approx(1.0)
        assert b["G"] == pytest.approx(b["E"] / (2 * (1 + PAPER_BEAM["nu"])))
        iz = b["a"] * b["b"] ** 3 / 12
        assert PAPER_KTHETA_FACTOR * b["E"] * iz / b["length"] == pytest.approx(1.0, rel=1e-12)
        # the rz diagonal of the tip spring is the cantilever 4EI_z/L
        k = np.asarray(g.stiffness)
        assert k[-1, -1] == pytest.approx(4 * b["E"] * iz / b["length"], rel=1e-12)
    assert math.isfinite(PAPER_BEAM["E"])



def test_drift_comparison_sees_number_changes_but_not_last_bits():
    """The drift tests compare numbers (rtol 1e-12), not text: a last-bit difference from
    another BLAS kernel passes; a changed parameter or structure does not."""
    text = (ROOT / "models" / "urdf" / "paper-c-s.urdf").read_text()
    j = text.index("stiffness", text.index("<vjm:"))
    m = re.search(r"(-?\d+\.\d+(?:e[-+]?\d+)?)", text[j:])
    start, end = j + m.start(1), j + m.end(1)
    x = float(m.group(1))
    assert x != 0.0

    def nudged(rel):
        return text[:start] + repr(x * (1 + rel)) + text[end:]

    assert urdf_differences(text, text) == []
    assert urdf_differences(text, nudged(1e-15)) == []
    assert urdf_differences(text, nudged(1e-9))
    assert urdf_differences(text, text.replace("</robot>", "<link name='extra'/></robot>"))
