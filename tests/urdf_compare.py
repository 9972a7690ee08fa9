"""Compare two URDF/XML texts as documents: same elements and attributes, numbers equal
within a tolerance (never as text: BLAS kernels differ in the last bit across CPUs)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET


def _numbers(s: str):
    try:
        return [float(t) for t in s.split()]
    except ValueError:
        return None


def _close(a: str, b: str, rtol: float, atol: float) -> bool:
    if a == b:
        return True
    na, nb = _numbers(a), _numbers(b)
    if na is None or nb is None or len(na) != len(nb) or not na:
        return False
    return all(math.isclose(x, y, rel_tol=rtol, abs_tol=atol) for x, y in zip(na, nb))


def urdf_differences(a: str, b: str, rtol: float = 1e-12, atol: float = 1e-14, limit: int = 5) -> list[str]:
    """Where the XML documents ``a`` and ``b`` differ (empty when they agree): element tags,
    attribute names, and values/texts — numeric ones (space-separated lists too) compared
    with ``|x − y| ≤ max(rtol·max(|x|, |y|), atol)``."""
    out: list[str] = []

    def walk(ea, eb, where):
        if len(out) >= limit:
            return
        here = f"{where}/{ea.tag}"
        if ea.tag != eb.tag:
            out.append(f"{where}: element {ea.tag} != {eb.tag}")
            return
        if set(ea.attrib) != set(eb.attrib):
            out.append(f"{here}: attributes {sorted(ea.attrib)} != {sorted(eb.attrib)}")
        for k in sorted(set(ea.attrib) & set(eb.attrib)):
            if not _close(ea.attrib[k], eb.attrib[k], rtol, atol):
                out.append(f"{here}@{k}: {ea.attrib[k]!r} != {eb.attrib[k]!r}")
        ta, tb = (ea.text or "").strip(), (eb.text or "").strip()
        if not _close(ta, tb, rtol, atol):
            out.append(f"{here} text: {ta[:60]!r} != {tb[:60]!r}")
        ca, cb = list(ea), list(eb)
        if len(ca) != len(cb):
            out.append(f"{here}: {len(ca)} children != {len(cb)}")
            return
        for i, (x, y) in enumerate(zip(ca, cb)):
            walk(x, y, f"{here}[{i}]")

    walk(ET.fromstring(a), ET.fromstring(b), "")
    return out
