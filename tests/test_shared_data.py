"""One ``pin.Data`` per model and thread (``vjm_pin.kinematics.shared``), placements without a
Data (``vjm_pin.model.placements``), and the lazy imports of issue 14 (spec schema, solver).

Pinocchio 4.1 allocates nv³ tensors in every Data (seconds and ~600 MB for the 231-coordinate
``orthoglide-loop-q0``), so every kinematics user of a solver shares one. Sharing is safe because
each user recomputes what it reads at its own configuration: the tests interleave users at
different configurations and compare, bit for bit, with private Datas.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import threading

import numpy as np
import pinocchio as pin
import pytest

import vjm_pin.kinematics.chain as chain_mod
import vjm_pin.kinematics.dead_loads as dead_loads_mod
import vjm_pin.kinematics.frames as frames_mod
import vjm_pin.solver.mechanism as mechanism_mod
from vjm_pin.exceptions import ArgumentError, SpecProblems
from vjm_pin.kinematics.chain import Kinematics
from vjm_pin.kinematics.closures import ClosureSet
from vjm_pin.kinematics.dead_loads import DeadLoads, Load
from vjm_pin.kinematics.frames import FrameKinematics
from vjm_pin.kinematics.shared import data_for
from vjm_pin.model.format import load_vjm
from vjm_pin.model.placements import frame_placements, joint_placements
from vjm_pin.model.registry import model_path, resolve_model
from vjm_pin.solver.mechanism import MechanismSolver

GRAVITY = np.array([0.0, 0.0, -9.80665])


def _fresh(name: str):
    """A newly loaded bundled model (its own pin.Model: no shared Data exists for it yet)."""
    return load_vjm(model_path(name))


def _same(a, b, where="result") -> None:
    """Recursive bit-for-bit equality of results (arrays, dataclasses, dicts, sequences)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape and a.dtype == b.dtype, where
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f"{where} differs"
    elif dataclasses.is_dataclass(a):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (u, v) in enumerate(zip(a, b)):
            _same(u, v, f"{where}[{i}]")
    elif isinstance(a, float) and isinstance(b, float) and np.isnan(a):
        assert np.isnan(b), where
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _solve_and_stiffness(vm, loads, wrench, gravity):
    solver = MechanismSolver(vm, loads, gravity)
    res = solver.solve(wrench=wrench)
    return res, solver.stiffness(res)


CASES = {
    "portal-frame": (
        [Load("top_left", [0.0, 0.0, -40.0]), Load("top_right", [0.0, 0.0, -40.0])],
        np.array([25.0, 0, 0, 0, 0, 0]),
    ),
    "four-bar": (
        [Load("coupler_point", [1.0, 0.0, -2.0]), Load("crank_link", [0.0, 0.0, -1.0, 0.0, 0.3, 0.0])],
        np.array([3.0, 0, -5.0, 0, 0, 0]),
    ),
    "orthoglide-q0": ([Load("leg2__platform", [0.0, 40.0, -30.0])], np.array([100.0, -50.0, 80.0, 1.0, 0, -2.0])),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_shared_data_gives_the_results_of_private_datas_bit_for_bit(name, monkeypatch):
    loads, wrench = CASES[name]
    shared_res, shared_k = _solve_and_stiffness(_fresh(name), loads, wrench, GRAVITY)
    assert shared_res.converged
    with monkeypatch.context() as m:
        caches = {}
        for mod in (frames_mod, chain_mod, dead_loads_mod, mechanism_mod):
            cache = caches[mod.__name__] = {}

            def private(model, cache=cache):
                hit = cache.get(id(model))
                if hit is None or hit[0] is not model:
                    hit = cache[id(model)] = (model, model.createData())
                return hit[1]

            m.setattr(mod, "data_for", private)
        private_res, private_k = _solve_and_stiffness(_fresh(name), loads, wrench, GRAVITY)
        # the private run really used separate Datas (frames, reference scales, link weights)
        assert sum(len(c) for c in caches.values()) >= 3
    _same(shared_res, private_res, "MechanismResult")
    _same(shared_k, private_k, "StiffnessResult")


def test_users_interleaved_at_different_configurations_read_their_own_kinematics():
    """Three users of one shared Data (end-frame Kinematics, FrameKinematics of closure frames,
    link weights on a model copy with gravity) evaluated in turn at different configurations give,
    bit for bit, what each gives alone on a model of its own."""
    vm = _fresh("four-bar")
    model = vm.model
    rng = np.random.default_rng(7)
    xs = [vm.reference + rng.normal(scale=0.2, size=model.nv) for _ in range(4)]
    # give the links mass so that the weights are not zero
    for i in range(1, model.njoints):
        model.inertias[i] = pin.Inertia(1.0 + i, np.array([0.01 * i, 0.0, 0.02]), np.diag([0.1, 0.2, 0.3]))

    def users(m):
        cs = ClosureSet(vm if m is model else m, None if m is model else vm.closures)
        return (
            Kinematics(m, vm.frame_id),
            FrameKinematics(m, cs.frame_ids),
            DeadLoads(m, [Load("coupler_point", [1.0, 2.0, -3.0])], GRAVITY),
        )

    def read(user, x):
        if isinstance(user, DeadLoads):
            st = user.evaluate(x)
            return (st.force, st.derivative, np.array(st.potential))
        if isinstance(user, Kinematics):
            st = user.evaluate(x)
            return (st.position, st.rotation, st.jacobian, st.hessian)
        return tuple(v for s in user.evaluate(x).values() for v in (s.position, s.rotation, s.jacobian, s.hessian))

    # alone: each user on a copy of the model of its own (its own Data), each configuration
    alone = []
    for k in range(3):
        own = users(model.copy())[k]
        alone.append([read(own, x) for x in xs])
    shared = users(model)
    assert all(u.data is data_for(model) for u in shared[:2])  # one Data for all three
    for step in range(3 * len(xs)):
        k = step % 3
        i = (step + k) % len(xs)  # the users sit at different configurations at every step
        _same(read(shared[k], xs[i]), alone[k][i], f"user {k} at x{i}")


def test_one_mechanism_solver_creates_one_data(monkeypatch):
    """Loading a closed model creates no pin.Data, a MechanismSolver (closures, dead loads, link
    weights) one, its solve, stiffness, siblings and re-referenced copies none."""
    counts = {"n": 0}
    original = pin.Model.createData

    def counted(self):
        counts["n"] += 1
        return original(self)

    monkeypatch.setattr(pin.Model, "createData", counted)
    vm = _fresh("four-bar")
    assert counts["n"] == 0
    solver = MechanismSolver(vm, [Load("coupler_point", [1.0, 0.0, -2.0])], GRAVITY)
    res = solver.solve(wrench=np.array([3.0, 0, -5.0, 0, 0, 0]))
    solver.stiffness(res)
    solver.sibling(follow_stable=False).solve(wrench=np.zeros(6))
    i = int(vm.q_idx[0])  # a passive joint (1-DoF joints: velocity index i is joint i + 1)
    moved = solver.at_reference(vm.with_positions({vm.model.names[i + 1]: vm.reference[i] + 0.01}))
    assert moved.vm is not vm
    assert res.converged
    assert counts["n"] == 1
    # another thread gets a Data of its own (a pin.Data is not thread-safe)
    seen = []
    t = threading.Thread(target=lambda: seen.append(data_for(vm.model)))
    t.start()
    t.join()
    assert counts["n"] == 2 and seen[0] is not data_for(vm.model)


def test_data_for_is_per_model_and_dropped_with_the_model():
    import gc
    import weakref

    from vjm_pin.kinematics.shared import shared_data_count

    a = _fresh("portal-frame").model
    b = a.copy()
    assert data_for(a) is data_for(a) and data_for(a) is not data_for(b)
    n = shared_data_count()
    ref = weakref.ref(data_for(b))
    del b
    gc.collect()
    assert ref() is None and shared_data_count() <= n - 1  # (other dead models may go too)
    with pytest.raises(ArgumentError, match="pinocchio.Model"):
        data_for("portal-frame")


def test_models_of_one_joint_tree_share_a_data_and_give_their_own_numbers():
    """``share_data``: the Orthoglide at Q1 on the Data of Q0 (one joint tree; the frame placements
    differ at round-off) solves, judges and stiffens bit for bit as on its own Data, with Q0's
    solver run on the same Data in between; a model of another tree is refused."""
    from vjm_pin.kinematics.shared import share_data

    q0, own, shared = _fresh("orthoglide-q0"), _fresh("orthoglide-q1"), _fresh("orthoglide-q1")
    d = -1e-3 * np.ones(3) / np.sqrt(3)

    def run(vm):
        solver = MechanismSolver(vm)
        res = solver.solve(deflection=d, held="x y z")
        return res, solver.stiffness(res)

    expected = run(own)
    assert share_data(shared.model, q0.model) is data_for(q0.model)
    assert data_for(shared.model) is data_for(q0.model) and data_for(own.model) is not data_for(q0.model)
    first = run(shared)
    other = run(q0)  # the same Data at Q0's configurations
    _same(first, expected)
    _same(run(shared), expected)
    assert not np.array_equal(other[0].x, expected[0].x)
    with pytest.raises(ArgumentError, match="joint tree"):
        share_data(_fresh("four-bar").model, q0.model)
    with pytest.raises(ArgumentError, match="pinocchio.Model"):
        share_data("orthoglide-q1", q0.model)


@pytest.mark.parametrize("name", ["four-bar", "orthoglide-q0"])
def test_placements_without_data_equal_pinocchio(name):
    vm = _fresh(name)
    model = vm.model
    data = model.createData()
    rng = np.random.default_rng(3)
    for x in (vm.reference, vm.reference + rng.normal(scale=0.3, size=model.nq)):
        pin.framesForwardKinematics(model, data, x)
        omf = frame_placements(model, x)
        omi = joint_placements(model, x)
        assert len(omf) == model.nframes and len(omi) == model.njoints
        # the same products as Pinocchio's; its revolute-specialised products may round entries of
        # ~1e-16 differently (seen: 1e-32 at reference poses), so equal to round-off of unit entries
        for mine, theirs in zip(omf, data.oMf):
            assert np.abs(mine.homogeneous - theirs.homogeneous).max() <= 1e-15
        for mine, theirs in zip(omi, data.oMi):
            assert np.abs(mine.homogeneous - theirs.homogeneous).max() <= 1e-15
    with pytest.raises(ArgumentError, match=f"{model.nq} finite numbers"):
        joint_placements(model, np.zeros(model.nq + 1))


# ----------------------------------------------------------------------------- lazy imports
def test_a_serial_analyze_imports_neither_pydantic_nor_the_mechanism_solver():
    code = (
        "import sys\n"
        "from vjm_pin.cli import main\n"
        "rc = main(['analyze', 'ur5', '--wrench', '0', '0', '-100'])\n"
        "print(rc, sorted(m for m in ('pydantic', 'vjm_pin.solver.mechanism') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "0 []"


def test_every_public_solver_name_is_importable_and_is_its_modules():
    import importlib

    from vjm_pin import solver

    for name in solver.__all__:
        value = getattr(solver, name)
        home = solver._LAZY.get(name)
        if home is not None:
            assert value is getattr(importlib.import_module(f"vjm_pin.solver.{home}"), name)
    assert set(solver.__all__) <= set(dir(solver))
    with pytest.raises(AttributeError):
        solver.NoSuchName  # noqa: B018


def test_spec_key_tables_are_the_schema_fields():
    from vjm_pin.model import spec

    assert spec.SPEC_KEYS == tuple(spec.SpringSpec.model_fields)
    assert spec.LINK_KEYS == tuple(spec.LinkSpec.model_fields)
    assert spec.BEAM_KEYS == tuple(spec.BeamSpec.model_fields)


VALID = [
    {"frame": "tool0", "actuators": {"a": 1e5, "b": 3, "c": None}, "positions": {"a": 0.3, "b": -1}},
    {"name": "r", "frame": "f", "task": "x y rz", "passive": ["p1", "p2"], "links": {}, "subdivide": 2},
    {"frame": "f", "task": ["x", "z"], "actuators": None, "positions": None, "name": None},
    {"positions": {}, "actuators": {}, "frame": "f"},
]
INVALID = [
    {"frame": "", "actuators": {"a": 1.0}},
    {"frame": "f", "actuators": {"a": -1.0}},
    {"frame": "f", "actuators": {"a": 0}},
    {"frame": "f", "positions": {"a": float("nan")}},
    {"frame": "f", "positions": {"a": True}},
    {"frame": "f", "task": "x x"},
    {"frame": "f", "task": "x q"},
    {"frame": "f", "task": []},
    {"frame": "f", "passive": "p1"},
    {"frame": "f", "passive": [""]},
    {"frame": "f", "subdivide": 0},
    {"frame": "f", "subdivide": True},
    {"frame": "f", "subdivide": 1.0},
    {"frame": "f", "frmae": "g"},
    {"frame": 3},
    {"frame": "f", "actuators": {"": 1.0}},
    {"frame": "f", "actuators": [1.0]},
]
PYDANTIC_ONLY = [  # valid, but outside the fast path: the pydantic schema decides
    {"frame": "f", "actuators": {"a": "1e5"}},
    {"frame": "f", "positions": {"a": np.float64(0.5)}},
    {"frame": "f", "links": {"l": {"stiffness": [[2.0]], "dofs": "rz"}}},
    {"frame": "f", "task": ("x", "y")},
]


@pytest.mark.parametrize("doc", VALID + INVALID + PYDANTIC_ONLY)
def test_the_fast_spec_path_returns_what_the_schema_returns(doc):
    from vjm_pin.model import spec

    fast = spec._fast_spec(doc)
    try:
        expected = spec.SpringSpec.model_validate(doc).model_dump(exclude_unset=True)
    except Exception:  # noqa: BLE001 - any validation error: the fast path must decline
        expected = None
    if doc in VALID:
        assert fast is not None
    if fast is not None:
        assert expected is not None
        _same(fast, expected, "spec")
        assert list(fast) == list(expected)  # same key order
        assert spec.read_spec(doc) == expected
    if expected is None:
        assert fast is None
        with pytest.raises(SpecProblems):
            spec.read_spec(doc)


def test_a_catalogue_robot_loads_the_same_with_and_without_the_fast_spec_path(monkeypatch):
    from vjm_pin.model import spec

    fast = resolve_model("ur5")
    monkeypatch.setattr(spec, "_fast_spec", lambda data: None)
    slow = resolve_model("ur5")
    assert fast.urdf == slow.urdf
