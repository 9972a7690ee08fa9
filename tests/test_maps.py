"""Workspace maps: indices against the solver, backends bit for bit, files, CLI."""

import csv
import json

import numpy as np
import pytest

from vjm_pin import EquilibriumSolver, load_vjm, loaded_stiffness
from vjm_pin.analysis.maps import (
    evaluate_pose,
    grid_poses,
    joint_limits,
    mapped_joints,
    parse_grid,
    run_map,
    sample_poses,
)
from vjm_pin.cli import main
from vjm_pin.exceptions import InputError, JointNotFound
from vjm_pin.model.paper_models import paper_model_urdf
from vjm_pin.model.robots import build_robot

SPRINGS = {
    "links": {
        "forearm_link": {
            "beam": {
                "section": "tube",
                "outer_diameter": 0.07,
                "wall": 0.0035,
                "E": 7e10,
                "nu": 0.33,
            }
        }
    }
}
W = np.array([10.0, 0.0, -100.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def ur5():
    return build_robot("ur5", springs=SPRINGS).vm


@pytest.fixture(scope="module")
def small(ur5):
    names, poses = sample_poses(ur5, 10, seed=4)
    return names, poses, run_map(ur5, names, poses, W, backend="serial")


def test_samples_within_limits_and_reproducible(ur5):
    names, a = sample_poses(ur5, 50, seed=1)
    _, b = sample_poses(ur5, 50, seed=1)
    _, c = sample_poses(ur5, 50, seed=2)
    assert names == mapped_joints(ur5) and len(names) == 6
    lim = joint_limits(ur5, names)
    assert np.all(a >= lim[:, 0]) and np.all(a <= lim[:, 1])
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_indices_agree_with_the_solver_and_their_definition(ur5, small):
    names, poses, res = small
    assert np.all(res.status == "ok") and np.all(res.stable)
    i = 3
    v = ur5.with_positions(dict(zip(names, poses[i])))
    eq = EquilibriumSolver(v, tol=1e-12).solve_wrench(W)
    assert np.allclose(res.deflection[i], eq.deflection, rtol=1e-6, atol=1e-12)
    # k_along: stiffness met by an extra force along f̂, by finite differences of re-solved equilibria
    fh = W[:3] / np.linalg.norm(W[:3])
    h = 0.5
    dp = []
    for s in (1, -1):
        w2 = W.copy()
        w2[:3] += s * h * fh
        dp.append(EquilibriumSolver(v, tol=1e-12).solve_wrench(w2).position)
    k_fd = 2 * h / (fh @ (dp[0] - dp[1]))
    assert res.k_along[i] == pytest.approx(k_fd, rel=1e-5)
    # k_min: the end free to rotate, 1/λ_max of the translational compliance block; the
    # weakest direction, so k_min ≤ k_along; and k_along ≤ the quotient of K_C's translational
    # block along f̂ (freeing the rotations can only soften: Schur complement)
    k6 = loaded_stiffness(v, eq).stiffness
    kt = k6[:3, :3]
    ct = np.linalg.inv(k6)[:3, :3]
    q = fh @ kt @ fh
    assert res.k_min[i] == pytest.approx(1.0 / np.linalg.eigvalsh(0.5 * (ct + ct.T))[-1], rel=1e-6)
    assert 0 < res.k_min[i] <= res.k_along[i] * (1 + 1e-9) and res.k_along[i] <= q * (1 + 1e-9)


def test_chunking_does_not_change_results(ur5, small):
    names, poses, res = small
    other = run_map(ur5, names, poses, W, backend="serial", chunk=3)
    for f in ("deflection", "k_along", "k_min", "p0"):
        assert np.array_equal(getattr(res, f), getattr(other, f))


def test_local_pool_and_dask_agree_bit_for_bit(ur5, small):
    names, poses, serial = small
    done = []
    local = run_map(ur5, names, poses, W, backend="local", workers=2, chunk=3, progress=done.append)
    dask = run_map(ur5, names, poses, W, backend="dask", workers=2, chunk=4)
    assert done[-1] == len(poses) and sorted(done) == done
    for r in (local, dask):
        for f in ("deflection", "k_along", "k_min", "p0", "stable", "status"):
            assert np.array_equal(getattr(r, f), getattr(serial, f)), f


def test_csv_npz_and_plot(tmp_path, small):
    _, _, res = small
    res.save(tmp_path / "m.csv")
    res.save(tmp_path / "m.npz")
    from vjm_pin.viz.plots import save_map_plot

    save_map_plot(res, tmp_path / "m.png")
    with open(tmp_path / "m.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(res.status)
    assert [float(r["dz_m"]) for r in rows] == res.deflection[:, 2].tolist()  # exact round trip
    assert [float(r["k_along_N_per_m"]) for r in rows] == res.k_along.tolist()
    z = np.load(tmp_path / "m.npz")
    assert np.array_equal(z["deflection"], res.deflection) and list(z["joints"]) == list(res.joints)
    assert (tmp_path / "m.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(InputError, match="csv or .npz"):
        res.save(tmp_path / "m.txt")


def test_grid_and_errors(ur5):
    grid = parse_grid(["shoulder_lift_joint=-2:-0.5:3", "elbow_joint=0.5:2:4"])
    names, poses = grid_poses(ur5, grid)
    assert poses.shape == (12, 2) and names == ["shoulder_lift_joint", "elbow_joint"]
    with pytest.raises(InputError, match="NAME=LO:HI:N"):
        parse_grid(["elbow_joint=0:1"])
    with pytest.raises(JointNotFound):
        grid_poses(ur5, {"nope": np.zeros(2)})
    with pytest.raises(InputError, match="positive"):
        sample_poses(ur5, 0)
    with pytest.raises(InputError, match="backend"):
        run_map(ur5, names, poses, W, backend="mpi")


def test_a_pose_without_finite_stiffness_is_reported_not_raised():
    vm = load_vjm(paper_model_urdf("a", "s"))  # straight rigid links: the axial stiffness is infinite
    row = evaluate_pose(vm, [], [], np.array([-0.5, 0, 0, 0, 0, 0]))
    assert row["status"] == "singular" and np.all(np.isnan(row["deflection"]))


def test_cli_map(tmp_path, capsys):
    out = tmp_path / "m.npz"
    argv = ["map", "ur5", "--samples", "6", "--backend", "serial", "--json", "--out", str(out)]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["poses"] == 6 and s["status"] == {"ok": 6} and out.is_file()
    z = np.load(out)
    d = np.linalg.norm(z["deflection"][:, :3], axis=1)
    assert s["deflection"]["max"] == pytest.approx(d.max())
    assert (
        main(["map", "ur5", "--samples", "3", "--scheduler", "tcp://x:1", "--backend", "local"])
        == 2
    )
    assert main(["map", "ur5", "--grid", "elbow_joint=0:1"]) == 2


def test_map_of_a_model_without_motors_says_what_to_do(capsys):
    from vjm_pin.cli import main

    assert main(["map", "paper-c-s", "--samples", "3"]) == 2
    err = capsys.readouterr().err
    assert "no actuated joint" in err and "--grid" in err and len(err.strip().splitlines()) == 1


def test_library_messages_name_parameters_and_the_cli_names_options(ur5, capsys):
    """sample_poses / parse_grid / grid_poses speak of their parameters (n, seed, grid); the
    CLI says --samples, --seed, --grid."""
    for call, word in (
        (lambda: sample_poses(ur5, 0), "n must be a positive integer"),
        (lambda: sample_poses(ur5, 3, seed=-1), "seed must"),
        (lambda: parse_grid(["elbow_joint=0:1"]), "grid item"),
        (lambda: parse_grid(["elbow_joint=1:0:3"]), "grid elbow_joint"),
    ):
        with pytest.raises(InputError) as e:
            call()
        assert word in str(e.value) and "--" not in str(e.value)
    for argv, option in (
        (["--samples", "0"], "--samples"),
        (["--samples", "3", "--seed", "-1"], "--seed"),
        (["--grid", "elbow_joint=1:0:3"], "--grid elbow_joint"),
    ):
        assert main(["map", "ur5", *argv, "--backend", "serial"]) == 2
        err = capsys.readouterr().err
        assert option in err and len(err.strip().splitlines()) == 1
