"""``vjm-pin models``: list the bundled models."""

from __future__ import annotations


def add_parser(sub):
    p = sub.add_parser("models", help="list the bundled VJM models", description="List the bundled VJM models (models/urdf).")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..registry import bundled_models, models_dir
    from .common import dump_json

    models = bundled_models()
    if args.json:
        print(dump_json({"models": {k: str(v) for k, v in models.items()}}))
    else:
        print(f"bundled models in {models_dir()}:")
        for name in models:
            print(f"  {name}")
    return 0
