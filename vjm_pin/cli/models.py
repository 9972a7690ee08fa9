"""``vjm-pin models``: list the bundled models, and with ``--robots`` the example-robot-data robots."""

from __future__ import annotations

EXAMPLES = (
    "vjm-pin models",
    "vjm-pin models --json",
    "vjm-pin models --robots",
)


def add_parser(sub):
    p = sub.add_parser(
        "models",
        help="list the bundled VJM models (--robots: the example-robot-data robots)",
        description=(
            "List the bundled VJM models (models/urdf). With --robots, list the robots of "
            "example-robot-data that MODEL may name (analysed with the defaults of vjm_pin.model.robots)."
        ),
    )
    p.add_argument("--robots", action="store_true", help="list the example-robot-data robots")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args) -> int:
    from vjm_pin.cli.common import dump_json, envelope
    from vjm_pin.model.registry import bundled_models, models_dir

    if args.robots:
        from vjm_pin.model.robots import robot_names, robot_source

        rows = {}
        for name in robot_names():
            try:
                src = robot_source(name)
                rows[name] = {
                    "urdf": str(src.urdf),
                    "srdf": None if src.srdf is None else str(src.srdf),
                    "reference_pose": src.ref_posture,
                    "free_flyer": src.free_flyer,
                }
            except Exception as e:  # noqa: BLE001 - listing must not stop at one broken entry
                rows[name] = {"error": str(e)}
        if args.json:
            print(dump_json(envelope("models", {"robots": rows}, {})))
        else:
            print("example-robot-data robots (free-flyer robots are analysed with a fixed base):")
            for name, r in rows.items():
                note = r.get("error") or ("free-flyer" if r["free_flyer"] else "")
                print(f"  {name:28s} {note}")
        return 0
    models = bundled_models()
    if args.json:
        print(dump_json(envelope("models", {"models": {k: str(v) for k, v in models.items()}}, {})))
    else:
        print(f"bundled models in {models_dir()}:")
        for name in models:
            print(f"  {name}")
    return 0
