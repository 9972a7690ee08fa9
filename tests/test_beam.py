"""Beam stiffness against closed forms of structural mechanics."""

import numpy as np
import pytest

from vjm_pin import SpecError
from vjm_pin.model.beam import Beam, rectangle_torsion_constant


@pytest.mark.parametrize("ratio,beta", [(1.0, 0.141), (1.5, 0.196), (2.0, 0.229), (2.5, 0.249), (3.0, 0.263), (4.0, 0.281), (10.0, 0.312)])
def test_rectangle_torsion_constant_matches_standard_table(ratio, beta):
    """J = β w t³ with the table of Timoshenko & Goodier (3 significant digits)."""
    t = 0.01
    assert rectangle_torsion_constant(t, ratio * t) / (ratio * t * t**3) == pytest.approx(beta, abs=6e-4)


def test_cantilever_stiffness_has_the_closed_form_blocks():
    """Inverse of the tip compliance: axial EA/L, bending [[12EI/L³, ∓6EI/L²], [∓6EI/L², 4EI/L]], torsion GJ/L."""
    E, nu, L, a, b = 7e10, 0.33, 0.8, 0.02, 0.05
    beam = Beam.from_dict({"length": L, "section": "rectangle", "a": a, "b": b, "E": E, "nu": nu})
    k = beam.stiffness()
    G = E / (2 * (1 + nu))
    iy, iz = b * a**3 / 12, a * b**3 / 12
    assert k[0, 0] == pytest.approx(E * a * b / L, rel=1e-10)
    assert k[1, 1] == pytest.approx(12 * E * iz / L**3, rel=1e-10)
    assert k[1, 5] == pytest.approx(-6 * E * iz / L**2, rel=1e-10)
    assert k[5, 5] == pytest.approx(4 * E * iz / L, rel=1e-10)
    assert k[2, 2] == pytest.approx(12 * E * iy / L**3, rel=1e-10)
    assert k[2, 4] == pytest.approx(6 * E * iy / L**2, rel=1e-10)
    assert k[4, 4] == pytest.approx(4 * E * iy / L, rel=1e-10)
    assert k[3, 3] == pytest.approx(G * rectangle_torsion_constant(a, b) / L, rel=1e-10)
    assert np.allclose(k, k.T) and np.linalg.eigvalsh(k).min() > 0


def test_tube_and_circle_sections():
    d, w = 0.09, 0.005
    tube = Beam.from_dict({"length": 0.4, "section": "tube", "outer_diameter": d, "wall": w, "E": 7e10, "G": 2.6e10})
    i = np.pi * (d**4 - (d - 2 * w) ** 4) / 64
    assert tube.properties.iy == pytest.approx(i) and tube.properties.torsion == pytest.approx(2 * i)
    circ = Beam.from_dict({"length": 0.4, "section": "circle", "diameter": d, "E": 7e10, "nu": 0.3})
    assert circ.properties.area == pytest.approx(np.pi * d**2 / 4)


@pytest.mark.parametrize(
    "bad,match",
    [
        ({"section": "rectangle", "a": 0.01, "E": 1e9, "nu": 0.3}, "needs 'b'"),
        ({"section": "hexagon", "a": 0.01, "E": 1e9, "nu": 0.3}, "unknown beam section"),
        ({"section": "circle", "diameter": 0.01, "E": 1e9}, "nu"),
        ({"section": "circle", "diameter": -0.01, "E": 1e9, "nu": 0.3}, "positive"),
        ({"section": "circle", "diameter": 0.01, "E": 1e9, "nu": 0.3, "color": 1}, "unknown beam keys"),
    ],
)
def test_bad_beam_specs_are_rejected(bad, match):
    with pytest.raises(SpecError, match=match):
        Beam.from_dict({"length": 1.0, **bad})
