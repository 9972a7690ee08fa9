"""``vjm-pin schema``: print the JSON Schema of a command's ``--json`` output."""

from __future__ import annotations

#: Commands with a ``--json`` output and a schema in ``vjm_pin/schemas/COMMAND.json``.
SCHEMAS = ("analyze", "curve", "critical", "map", "view", "models")

EXAMPLES = (
    "vjm-pin schema analyze",
    "vjm-pin schema curve",
    "vjm-pin schema view",
)


def add_parser(sub):
    p = sub.add_parser(
        "schema",
        help="print the JSON Schema (draft 2020-12) of a command's --json output",
        description=(
            "Print the JSON Schema (draft 2020-12) that the --json output of COMMAND follows. "
            "Every output has 'version' (the package version), 'command' and 'units' (the SI "
            "unit of each quantity) first. The schemas ship in the package (vjm_pin/schemas)."
        ),
    )
    p.add_argument("name", metavar="COMMAND", choices=SCHEMAS, help=", ".join(SCHEMAS))
    p.set_defaults(func=run)


def load_schema(name: str) -> dict:
    """The schema of the ``--json`` output of command ``name`` (a dict)."""
    import json
    from importlib import resources

    from vjm_pin.exceptions import InputError

    if name not in SCHEMAS:
        raise InputError(f"no schema for '{name}'; one of {', '.join(SCHEMAS)}")
    text = resources.files("vjm_pin").joinpath("schemas", f"{name}.json").read_text("utf-8")
    return json.loads(text)


def run(args) -> int:
    import json

    print(json.dumps(load_schema(args.name), indent=2, ensure_ascii=False))
    return 0
