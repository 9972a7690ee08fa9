"""The spring specification: its schema, and reading it from YAML or a dict.

The keys are documented in :mod:`vjm_pin.model.generator` and ``docs/format.md``. The schema is
written as pydantic models (one declaration gives the key names, the types, the allowed
values and the YAML path of every problem): :func:`read_spec` validates the whole
document and raises one :class:`~vjm_pin.exceptions.SpecProblems` listing every problem as
``yaml.path: what is wrong`` (``links.forearm_link.beam.E: expected a number, got 'abc'``).

Checks that need the URDF (joint and link names, the shape of a stiffness matrix against
its ``dofs``, positive definiteness) stay in :func:`vjm_pin.model.generator.generate_vjm`.

Import time (issue 14): pydantic is imported and the models are built on first use
(:func:`_schema`; the names ``SpringSpec``, ``LinkSpec``, ``BeamSpec`` … stay importable through
the module ``__getattr__``). A plain valid document without link springs — what the robot
catalogue passes for a one-shot ``vjm-pin analyze ur5`` — is read by :func:`_fast_spec` with the
schema's own value validators and no pydantic; anything else goes through the schema.
"""

from __future__ import annotations

import copy
import difflib
import math
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from vjm_pin.exceptions import ArgumentError, SpecProblems

COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")
SECTION_DIMS = {"rectangle": ("a", "b"), "circle": ("diameter",), "tube": ("outer_diameter", "wall")}


def _show(v: Any) -> str:
    """A short, one-line rendering of a value in an error message."""
    if isinstance(v, dict):
        return "a mapping"
    r = repr(v)
    return r if len(r) <= 40 else r[:37] + "..."


def _number(v: Any, *, positive: bool = False) -> float:
    """A finite number (YAML 1.1 reads ``1e5`` as a string: numeric strings are accepted);
    booleans are refused."""
    if isinstance(v, bool) or not isinstance(v, (int, float, str, np.integer, np.floating)):
        raise ValueError(f"expected a number, got {_show(v)}")  # noqa: TRY004 - pydantic reports ValueError
    try:
        f = float(v)
    except ValueError:
        raise ValueError(f"expected a number, got {_show(v)}") from None
    if not math.isfinite(f):
        raise ValueError(f"expected a finite number, got {_show(v)}")
    if positive and f <= 0.0:
        raise ValueError(f"must be positive, got {_show(v)}")
    return f


def _name(v: Any) -> str:
    if not isinstance(v, str) or not v:
        raise ValueError(f"expected a name (a non-empty string), got {_show(v)}")
    return v


def _components(v: Any) -> list[str]:
    if isinstance(v, str):
        v = v.split()
    if not isinstance(v, list):
        raise ValueError(f"expected a list of components from {' '.join(COMPONENTS)}, got {_show(v)}")  # noqa: TRY004
    bad = [c for c in v if c not in COMPONENTS]
    if bad:
        raise ValueError(f"{', '.join(repr(c) for c in bad)} not among {' '.join(COMPONENTS)}")
    if not v or len(set(v)) != len(v):
        raise ValueError(f"components must be distinct and non-empty, got {_show(v)}")
    return list(v)


def _positive_int(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
        raise ValueError(f"expected a positive integer, got {_show(v)}")
    return int(v)


#: The top-level keys of a spring specification (the fields of :class:`SpringSpec`, in order).
SPEC_KEYS = ("name", "frame", "task", "actuators", "passive", "positions", "links", "subdivide")
#: The keys of ``links.<link>`` (:class:`LinkSpec`) and of ``links.<link>.beam`` (:class:`BeamSpec`).
LINK_KEYS = ("beam", "stiffness", "dofs", "rest")
BEAM_KEYS = ("length", "section", "a", "b", "diameter", "outer_diameter", "wall", "E", "nu", "G")

#: Names of the pydantic schema, built on first use (:func:`_schema`): importing pydantic and
#: building the models costs ~0.3–0.5 s, more than a one-shot ``vjm-pin analyze`` of a catalogue
#: robot needs (its spec takes :func:`_fast_spec`). ``from vjm_pin.model.spec import LinkSpec``
#: still works (module ``__getattr__``, PEP 562).
_SCHEMA_NAMES = ("Number", "Positive", "Name", "Components", "PositiveInt", "BeamSpec", "LinkSpec", "SpringSpec")
_SCHEMA: dict[str, Any] = {}


def _schema() -> dict[str, Any]:
    """The pydantic models of the specification (built once)."""
    if _SCHEMA:
        return _SCHEMA
    from typing import Annotated, Literal

    from pydantic import BaseModel, BeforeValidator, ConfigDict, model_validator

    Number = Annotated[float, BeforeValidator(_number)]
    Positive = Annotated[float, BeforeValidator(partial(_number, positive=True))]
    Name = Annotated[str, BeforeValidator(_name)]
    Components = Annotated[list[str], BeforeValidator(_components)]
    PositiveInt = Annotated[int, BeforeValidator(_positive_int)]

    class _Strict(BaseModel):
        model_config = ConfigDict(extra="forbid")

    class BeamSpec(_Strict):
        """``links.<link>.beam``: a link as a cantilever beam (:mod:`vjm_pin.model.beam`); SI units."""

        length: Positive | None = None
        section: Literal["rectangle", "circle", "tube"]
        a: Positive | None = None
        b: Positive | None = None
        diameter: Positive | None = None
        outer_diameter: Positive | None = None
        wall: Positive | None = None
        E: Positive
        nu: Number | None = None
        G: Positive | None = None

        @model_validator(mode="after")
        def _consistent(self):
            if (self.nu is None) == (self.G is None):
                raise ValueError("give exactly one of Poisson's ratio 'nu' or shear modulus 'G' (Pa)")
            if self.nu is not None and not -1.0 < self.nu <= 0.5:
                raise ValueError(f"Poisson's ratio 'nu' must be in (-1, 0.5], got {self.nu:g}")
            need = SECTION_DIMS[self.section]
            given = [d for dims in SECTION_DIMS.values() for d in dims if getattr(self, d) is not None]
            missing = [d for d in need if d not in given]
            extra = [d for d in given if d not in need]
            if missing or extra:
                raise ValueError(
                    f"section '{self.section}' takes {' and '.join(need)} (m)"
                    + (f"; missing {', '.join(missing)}" if missing else "")
                    + (f"; does not take {', '.join(extra)}" if extra else "")
                )
            if self.section == "tube" and 2.0 * self.wall > self.outer_diameter:
                raise ValueError(f"tube wall {self.wall:g} m is thicker than half the diameter {self.outer_diameter:g} m")
            return self

    class LinkSpec(_Strict):
        """``links.<link>``: a link spring at the link tip, from a beam or a stiffness matrix."""

        beam: BeamSpec | None = None
        stiffness: list[list[Number]] | None = None
        dofs: Components = list(COMPONENTS)  # noqa: RUF012 - a pydantic field default (copied per instance)
        rest: list[Number] | None = None

        @model_validator(mode="after")
        def _consistent(self):
            if (self.beam is None) == (self.stiffness is None):
                raise ValueError("give exactly one of 'beam' or 'stiffness'")
            if self.rest is not None and len(self.rest) != len(self.dofs):
                raise ValueError(f"'rest' has {len(self.rest)} values for {len(self.dofs)} dofs {' '.join(self.dofs)}")
            return self

    class SpringSpec(_Strict):
        """The whole specification (keys documented in :mod:`vjm_pin.model.generator`)."""

        name: Name | None = None
        frame: Name | None = None
        task: Components | None = None
        actuators: dict[Name, Positive | None] | None = None
        passive: list[Name] | None = None
        positions: dict[Name, Number] | None = None
        links: dict[Name, LinkSpec] | None = None
        subdivide: PositiveInt | None = None

    names = dict(locals())
    _SCHEMA.update({k: names[k] for k in _SCHEMA_NAMES})
    return _SCHEMA


def __getattr__(name: str):
    if name in _SCHEMA_NAMES:
        return _schema()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _known_keys(loc: tuple) -> list[str]:
    """Keys allowed in the mapping at ``loc`` (the location of an unknown key)."""
    parent = loc[:-1]
    if len(parent) == 2 and parent[0] == "links":
        return list(LINK_KEYS)
    if len(parent) == 3 and parent[0] == "links" and parent[2] == "beam":
        return list(BEAM_KEYS)
    return list(SPEC_KEYS)


def _path(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part == "[key]":
            out += " (key)"
        else:
            out += ("." if out else "") + str(part)
    return out or "(document)"


def _problem(err: dict) -> str:
    """One pydantic error as ``path: message``."""
    loc, kind, got = tuple(err["loc"]), err["type"], err.get("input")
    if kind == "extra_forbidden":
        known = _known_keys(loc)
        close = difflib.get_close_matches(str(loc[-1]), known, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        msg = f"unknown key; {hint}known keys: {', '.join(known)}"
    elif kind == "missing":
        msg = "required key is missing"
    elif kind == "value_error":
        msg = str(err["ctx"]["error"]) if "ctx" in err else err["msg"]
    elif kind == "list_type":
        msg = f"expected a list, got {_show(got)}"
    elif kind in ("dict_type", "model_type", "model_attributes_type"):
        msg = f"expected a mapping, got {_show(got)}"
    elif kind == "literal_error":
        msg = f"expected one of {err['ctx']['expected']}, got {_show(got)}"
    else:  # pragma: no cover - types the schema above does not produce
        msg = f"{err['msg']} (got {_show(got)})"
    return f"{_path(loc)}: {msg}"


def _document_order(data: Any, loc: tuple) -> tuple:
    """Sort key of an error location: the position of each key in its mapping (list index
    for lists), so that problems are listed in the order of the document."""
    out = []
    node = data
    for part in loc:
        if isinstance(node, dict):
            keys = list(node)
            out.append(keys.index(part) if part in keys else len(keys))
            node = node.get(part)
        elif isinstance(node, list) and isinstance(part, int):
            out.append(part)
            node = node[part] if part < len(node) else None
        else:
            out.append(0)
            node = None
    return tuple(out)


class _UniqueKeyLoader:
    """A ``yaml.SafeLoader`` that refuses a key given twice in one mapping (PyYAML keeps the
    last one silently)."""

    _cls = None

    @classmethod
    def get(cls):
        if cls._cls is None:
            import yaml

            class Loader(yaml.SafeLoader):
                def construct_mapping(self, node, deep=False):
                    if isinstance(node, yaml.MappingNode):
                        self.flatten_mapping(node)
                    seen = set()
                    for key_node, _ in node.value:
                        key = self.construct_object(key_node, deep=deep)
                        try:
                            dup = key in seen
                            seen.add(key)
                        except TypeError:
                            dup = False
                        if dup:
                            raise yaml.constructor.ConstructorError(
                                None, None, f"key '{key}' is given twice", key_node.start_mark
                            )
                    return super().construct_mapping(node, deep)

            cls._cls = Loader
        return cls._cls


def _load_yaml(text: str, label: str) -> Any:
    import yaml

    try:
        return yaml.load(text, Loader=_UniqueKeyLoader.get())  # a SafeLoader subclass
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        raise SpecProblems(label, [f"{where}not valid YAML: {e.problem or e.context}"]) from None
    except yaml.YAMLError as e:  # pragma: no cover - errors without a position
        raise SpecProblems(label, [f"not valid YAML: {str(e).splitlines()[0]}"]) from None


def _read_file(p: Path) -> str:
    label = str(p)
    if p.is_dir():
        raise SpecProblems(label, ["is a folder, not a YAML file"])
    if not p.is_file():
        raise SpecProblems(label, ["file not found"])
    try:
        data = p.read_bytes()
    except OSError as e:
        raise SpecProblems(label, [f"cannot read the file ({e.strerror or e})"]) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise SpecProblems(
            label, [f"not a YAML text file (not UTF-8: byte 0x{data[e.start]:02x} at offset {e.start})"]
        ) from None


def _fast_items(d: Any, value_check) -> dict | None:
    """A mapping of names to checked values, or None when not a plain dict of non-empty str keys."""
    if type(d) is not dict:
        return None
    out = {}
    for k, v in d.items():
        if type(k) is not str or not k:
            return None
        out[k] = value_check(v)
    return out


def _fast_number(v: Any, positive: bool = False) -> float:
    if type(v) not in (int, float):  # strings, numpy scalars, booleans: the pydantic path
        raise ValueError
    return _number(v, positive=positive)


def _fast_spec(data: dict) -> dict | None:
    """The result of :func:`read_spec` for a plain, valid document without ``links``
    entries, without pydantic; None for anything else (the pydantic schema then decides and
    reports). Accepts only exact ``dict``/``list``/``str``/``int``/``float`` values and runs the
    schema's own validators (:func:`_number`, :func:`_name`, :func:`_components`,
    :func:`_positive_int`), so it returns what ``SpringSpec.model_validate(data).model_dump(
    exclude_unset=True)`` returns (``tests/test_shared_data.py`` compares the two)."""
    if type(data) is not dict or any(k not in SPEC_KEYS for k in data):
        return None
    try:
        out: dict[str, Any] = {}
        for key in SPEC_KEYS:
            if key not in data:
                continue
            v = data[key]
            if v is None:
                out[key] = None
            elif key in ("name", "frame"):
                if type(v) is not str:
                    return None
                out[key] = _name(v)
            elif key == "task":
                if type(v) not in (str, list) or (type(v) is list and any(type(c) is not str for c in v)):
                    return None
                out[key] = _components(v)
            elif key == "actuators":
                r = _fast_items(v, lambda a: None if a is None else _fast_number(a, True))
                if r is None:
                    return None
                out[key] = r
            elif key == "positions":
                r = _fast_items(v, _fast_number)
                if r is None:
                    return None
                out[key] = r
            elif key == "passive":
                if type(v) is not list or any(type(n) is not str for n in v):
                    return None
                out[key] = [_name(n) for n in v]
            elif key == "links":
                if type(v) is not dict or v:  # link springs: the pydantic path
                    return None
                out[key] = {}
            else:  # subdivide
                if type(v) is not int:
                    return None
                out[key] = _positive_int(v)
        return out
    except ValueError:
        return None


def read_spec(source, *, require_frame: bool = True) -> dict:
    """Read and validate a spring specification.

    Args:
        source: A dict, a YAML file path (``str`` or :class:`~pathlib.Path`) or YAML text (a
            ``str`` with a newline or starting with ``{``).
        require_frame: Whether ``frame`` must be given (the generator needs it; a robot's
            defaults supply it).

    Returns:
        A new dict with only the keys given, numbers as floats, ``task``/``dofs`` as lists.

    Raises:
        SpecProblems: every problem of the document at once (file name and YAML path each).
        ArgumentError: ``source`` is of another type.
    """
    if isinstance(source, dict):
        data, label = copy.deepcopy(source), "<dict>"
    elif isinstance(source, str) and ("\n" in source or source.lstrip().startswith("{")):
        label = "<YAML text>"
        data = _load_yaml(source, label)
    elif isinstance(source, (str, Path)) and str(source).strip():
        label = str(source)
        data = _load_yaml(_read_file(Path(source)), label)
    else:
        raise ArgumentError(
            "the spring specification must be a dict, a YAML file path or YAML text, "
            f"got {type(source).__name__} {_show(source)}"
        )
    if data is None:
        raise SpecProblems(label, [f"empty document: expected a mapping with keys {', '.join(SPEC_KEYS)}"])
    if not isinstance(data, dict):
        raise SpecProblems(label, [f"expected a mapping with keys {', '.join(SPEC_KEYS)}, got {_show(data)}"])
    if not (require_frame and data.get("frame") is None):
        fast = _fast_spec(data)
        if fast is not None:
            return fast
    from pydantic import ValidationError

    problems: list[str] = []
    try:
        spec = _schema()["SpringSpec"].model_validate(data)
    except ValidationError as e:
        errors = sorted(e.errors(), key=lambda err: _document_order(data, tuple(err["loc"])))
        problems = [_problem(err) for err in errors]
        spec = None
    if require_frame and data.get("frame") is None and not any(p.startswith("frame:") for p in problems):
        problems.insert(0, "frame: required key is missing (the end (task) frame: a link of the URDF)")
    if problems:
        raise SpecProblems(label, problems)
    return spec.model_dump(exclude_unset=True)
