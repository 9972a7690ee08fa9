"""Cantilever-beam stiffness of a link, for the 6-D virtual springs of the VJM model.

The beam frame has its x axis along the beam (from the root to the tip), y and z
along the principal axes of the section. A rectangular section has its side ``a``
along z and its side ``b`` along y (as in §6.1.5 of the paper: "the smaller value
``a`` corresponds to z-direction").

The tip compliance of an Euler–Bernoulli cantilever clamped at its root, for a
wrench ``(Fx, Fy, Fz, Mx, My, Mz)`` at the tip (N, N·m) and the tip deflection
``(dx, dy, dz, rx, ry, rz)`` (m, rad), all in the beam frame, is::

    dx = L/(E A) Fx
    dy = L³/(3 E I_z) Fy + L²/(2 E I_z) Mz        rz =  L²/(2 E I_z) Fy + L/(E I_z) Mz
    dz = L³/(3 E I_y) Fz − L²/(2 E I_y) My        ry = −L²/(2 E I_y) Fz + L/(E I_y) My
    rx = L/(G J) Mx

and the tip stiffness is its inverse (the ±L²/2EI terms couple bending and rotation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vjm_pin.exceptions import SpecError

SECTIONS = ("rectangle", "circle", "tube")


def _positive(value, name: str) -> float:
    """``value`` as a positive finite float; :class:`SpecError` naming ``name`` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SpecError(f"beam '{name}' must be a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0.0:
        raise SpecError(f"beam '{name}' must be positive and finite, got {value!r}")
    return v


def rectangle_torsion_constant(a: float, b: float, terms: int = 50) -> float:
    """Saint-Venant torsion constant of a solid rectangle (m⁴).

    ``J = β · w · t³`` with ``t = min(a, b)``, ``w = max(a, b)`` and the series of
    Timoshenko & Goodier (Theory of Elasticity, §109)::

        β = 1/3 · [1 − (192/π⁵)(t/w) Σ_{n=1,3,5,…} tanh(nπw/(2t)) / n⁵]

    which gives the standard table (β = 0.141 for w/t = 1, 0.229 for 2, 0.249 for
    2.5, 0.263 for 3, 0.312 for 10, 1/3 as w/t → ∞).
    """
    t, w = (a, b) if a <= b else (b, a)
    n = np.arange(1, 2 * terms, 2, dtype=float)
    s = np.sum(np.tanh(n * math.pi * w / (2.0 * t)) / n**5)
    beta = (1.0 - 192.0 / math.pi**5 * (t / w) * s) / 3.0
    return float(beta * w * t**3)


@dataclass(frozen=True)
class SectionProperties:
    """Area and second moments of a beam section.

    Attributes:
        area: Cross-section area A (m²).
        iy: Second moment about the beam-frame y axis, I_y = ∫ z² dA (m⁴); bending in z.
        iz: Second moment about the beam-frame z axis, I_z = ∫ y² dA (m⁴); bending in y.
        torsion: Torsion constant J (m⁴).
    """

    area: float
    iy: float
    iz: float
    torsion: float


def section_properties(section: str, **dims: float) -> SectionProperties:
    """Section properties of a rectangle (``a`` along z, ``b`` along y), circle
    (``diameter``) or thin/thick tube (``outer_diameter``, ``wall``); dimensions in m."""

    def need(*names: str) -> list[float]:
        vals = []
        for name in names:
            if name not in dims:
                raise SpecError(f"beam section '{section}' needs '{name}'")
            try:
                vals.append(_positive(dims[name], name))
            except SpecError as e:
                raise SpecError(f"beam section '{section}': {e}") from None
        extra = set(dims) - set(names)
        if extra:
            raise SpecError(
                f"beam section '{section}' does not take {sorted(extra)}; it takes {list(names)}"
            )
        return vals

    if section == "rectangle":
        a, b = need("a", "b")
        return SectionProperties(a * b, b * a**3 / 12.0, a * b**3 / 12.0, rectangle_torsion_constant(a, b))
    if section == "circle":
        (d,) = need("diameter")
        i = math.pi * d**4 / 64.0
        return SectionProperties(math.pi * d**2 / 4.0, i, i, 2.0 * i)
    if section == "tube":
        d, wall = need("outer_diameter", "wall")
        if 2.0 * wall > d:
            raise SpecError(f"beam section 'tube': wall {wall} m is thicker than half the diameter {d} m")
        di = d - 2.0 * wall
        i = math.pi * (d**4 - di**4) / 64.0
        return SectionProperties(math.pi * (d**2 - di**2) / 4.0, i, i, 2.0 * i)
    raise SpecError(f"unknown beam section '{section}'; choose one of {list(SECTIONS)}")


def cantilever_compliance(length: float, props: SectionProperties, E: float, G: float) -> np.ndarray:
    """Tip compliance (6, 6) of a clamped beam in the beam frame (m/N, rad/(N·m), …).

    Rows/columns ordered (x, y, z, rx, ry, rz); see the module docstring.
    """
    L = float(length)
    c = np.zeros((6, 6))
    c[0, 0] = L / (E * props.area)
    c[1, 1] = L**3 / (3.0 * E * props.iz)
    c[1, 5] = c[5, 1] = L**2 / (2.0 * E * props.iz)
    c[5, 5] = L / (E * props.iz)
    c[2, 2] = L**3 / (3.0 * E * props.iy)
    c[2, 4] = c[4, 2] = -(L**2) / (2.0 * E * props.iy)
    c[4, 4] = L / (E * props.iy)
    c[3, 3] = L / (G * props.torsion)
    return c


@dataclass(frozen=True)
class Beam:
    """A link modelled as a cantilever beam.

    Attributes:
        length: Beam length L (m).
        section: ``"rectangle"``, ``"circle"`` or ``"tube"``.
        dims: Section dimensions (m): ``a``, ``b`` | ``diameter`` | ``outer_diameter``, ``wall``.
        E: Young's modulus (Pa).
        G: Shear modulus (Pa).
    """

    length: float
    section: str
    dims: dict
    E: float
    G: float

    @classmethod
    def from_dict(cls, d: dict, length: float | None = None) -> Beam:
        """Build from a spec mapping: ``length`` (m, or given), ``section``, its dimensions,
        ``E`` and either ``nu`` or ``G``. Unknown keys raise :class:`SpecError`."""
        if not isinstance(d, dict):
            raise SpecError(f"beam must be a mapping of its parameters, got {type(d).__name__} {d!r}")
        d = dict(d)
        known = {"length", "section", "E", "nu", "G"}
        L = d.pop("length", length)
        if L is None:
            raise SpecError("beam needs 'length' (m)")
        section = d.pop("section", None)
        if section is None:
            raise SpecError("beam needs 'section' (rectangle, circle or tube)")
        if "E" not in d:
            raise SpecError("beam needs Young's modulus 'E' (Pa)")
        E = _positive(d.pop("E"), "E")
        nu = d.pop("nu", None)
        G = d.pop("G", None)
        if (nu is None) == (G is None):
            raise SpecError("beam needs exactly one of Poisson's ratio 'nu' or shear modulus 'G' (Pa)")
        if G is not None:
            G = _positive(G, "G")
        else:
            try:
                nu = float(nu)
            except (TypeError, ValueError):
                raise SpecError(f"beam 'nu' must be a number, got {nu!r}") from None
            if not -1.0 < nu <= 0.5:
                raise SpecError(f"beam Poisson's ratio 'nu' must be in (-1, 0.5], got {nu!r}")
            G = E / (2.0 * (1.0 + nu))
        L = _positive(L, "length")
        unknown = set(d) - {"a", "b", "diameter", "outer_diameter", "wall"}
        if unknown:
            raise SpecError(f"unknown beam keys {sorted(unknown)}; known: {sorted(known | {'a', 'b', 'diameter', 'outer_diameter', 'wall'})}")
        dims = {k: _positive(v, k) for k, v in d.items()}
        section_properties(section, **dims)  # validates
        return cls(L, section, dims, E, G)

    def to_dict(self) -> dict:
        return {"length": self.length, "section": self.section, **self.dims, "E": self.E, "G": self.G}

    @property
    def properties(self) -> SectionProperties:
        return section_properties(self.section, **self.dims)

    def compliance(self) -> np.ndarray:
        """Tip compliance (6, 6), beam frame; see :func:`cantilever_compliance`."""
        return cantilever_compliance(self.length, self.properties, self.E, self.G)

    def stiffness(self) -> np.ndarray:
        """Tip stiffness (6, 6) = inverse of the full tip compliance, beam frame
        (N/m, N, N·m/rad)."""
        k = np.linalg.inv(self.compliance())
        return 0.5 * (k + k.T)

    def split(self, k: int) -> Beam:
        """The beam of one of ``k`` equal sub-links (length L/k)."""
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise SpecError(f"split(k): k must be a positive integer (number of sub-links), got {k!r}")
        return Beam(self.length / k, self.section, dict(self.dims), self.E, self.G)
