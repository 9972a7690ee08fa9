"""Write the bundled paper models ``models/urdf/paper-{a,b,c}-{s,pi,z}.urdf``.

One source of truth: the rigid chain of eq. (34) (:func:`vjm_pin.model.paper_models.rigid_chain_urdf`)
and the spring specs (:func:`vjm_pin.model.paper_models.paper_spec`). ``tests/test_models.py``
regenerates them and fails if a committed file differs. Never edit the URDFs by hand.

Usage: ``python scripts/make_paper_models.py [--out models/urdf]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vjm_pin.model.paper_models import PAPER_BEAM, POSTURES, paper_model_urdf


def paper_models() -> dict[str, str]:
    """File name → URDF text of every bundled paper model."""
    out = {}
    for model in ("a", "b", "c"):
        for posture in POSTURES:
            kw = {} if model == "a" else {"beam": PAPER_BEAM}
            out[f"paper-{model}-{posture}.urdf"] = paper_model_urdf(model, posture, **kw)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(Path(__file__).resolve().parent.parent / "models" / "urdf"))
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in paper_models().items():
        (out / name).write_text(text)
        print(out / name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
