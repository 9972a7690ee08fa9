"""``vjm-pin view MODEL --map MAP``: a stiffness map file (``vjm-pin map --out``) drawn as
coloured points over the robot: the points are the map's end positions, the colours follow
the values on the stated scale, poses not solved are grey, bad files are one-line errors."""

from __future__ import annotations

import csv
import json
import re

import matplotlib
import numpy as np
import pytest

N_POSES = 12


@pytest.fixture(scope="module")
def ur5_map(tmp_path_factory):
    """A small map of ur5 written by the CLI, as .npz and .csv."""
    from vjm_pin.cli import main

    d = tmp_path_factory.mktemp("map")
    for ext in ("npz", "csv"):
        code = main(["map", "ur5", "--samples", str(N_POSES), "--backend", "serial",
                     "--out", str(d / f"m.{ext}"), "--quiet", "--no-progress"])
        assert code == 0
    return d / "m.npz", d / "m.csv"


def _setup(text: str) -> dict:
    return json.loads(re.search(r"var setup = (\{.*?\});\n", text, re.DOTALL).group(1))


def test_map_points_are_the_end_positions_coloured_on_the_scale(ur5_map):
    from vjm_pin.viz.map_cloud import map_points, read_map

    npz, csv_path = ur5_map
    z = np.load(npz)
    for path in (npz, csv_path):
        cloud = read_map(path)
        np.testing.assert_allclose(cloud.p0, z["p0"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(cloud.k_min, z["k_min"], rtol=1e-12)
        pts = map_points(cloud, "k_min")
        k = z["k_min"]
        assert pts["range"] == pytest.approx((k.min(), k.max()), rel=1e-12)
        cmap = matplotlib.colormaps["viridis"]
        np.testing.assert_allclose(pts["colors"][np.argmin(k)], cmap(0.0)[:3], atol=1e-9)
        np.testing.assert_allclose(pts["colors"][np.argmax(k)], cmap(1.0)[:3], atol=1e-9)
        # log scale: the geometric mean of the extremes maps to the middle of the colour map
        mid = np.sqrt(k.min() * k.max())
        assert pts["legend"][2][1] == f"k_min = {mid:.3g} N/m"
        np.testing.assert_allclose(pts["legend"][2][0][:3], cmap(0.5)[:3], atol=1e-9)
    defl = map_points(read_map(npz), "deflection")
    dn = np.linalg.norm(z["deflection"][:, :3], axis=1)
    assert defl["range"] == pytest.approx((dn.min(), dn.max()), rel=1e-12)
    assert defl["legend"][0][1] == f"|δ| = {dn.max() * 1e3:.3g} mm"


def test_view_map_page_json_and_unsolved_poses(ur5_map, tmp_path, capsys):
    from vjm_pin.cli import main

    npz, csv_path = ur5_map
    page = tmp_path / "map.html"
    assert main(["view", "ur5", "--map", str(npz), "--html", str(page), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["mode"] == "map" and out["frames"] == []
    assert out["map"]["points"] == N_POSES and out["map"]["not_solved"] == 0
    legend = [e["text"] for e in _setup(page.read_text(encoding="utf-8"))["legend"]]
    assert sum(t.startswith("k_min = ") for t in legend) == 5

    # one pose marked as not solved: drawn grey and counted in the legend
    rows = list(csv.DictReader(csv_path.open(newline="")))
    rows[3]["status"], rows[3]["k_min_N_per_m"] = "singular", "nan"
    bad = tmp_path / "bad.csv"
    with bad.open("w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=list(rows[0]))
        wr.writeheader()
        wr.writerows(rows)
    page2 = tmp_path / "map2.html"
    assert main(["view", "ur5", "--map", str(bad), "--color-by", "deflection",
                 "--html", str(page2), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["map"]["not_solved"] == 1 and out["map"]["color_by"] == "deflection"
    legend = [e["text"] for e in _setup(page2.read_text(encoding="utf-8"))["legend"]]
    assert f"not solved (1 of {N_POSES} poses)" in legend


@pytest.mark.parametrize(
    "extra, word",
    [
        (["--map", "nothere.npz"], "nothere.npz"),
        (["--map", "m.txt"], ".npz or .csv"),
        (["--map", "{npz}", "--wrench", "1", "0", "0"], "--wrench"),
        (["--color-by", "deflection", "--wrench", "1", "0", "0"], "--color-by"),
        (["--map", "{garbage}"], "not a map"),
    ],
)
def test_view_map_bad_input_is_a_one_line_error(ur5_map, tmp_path, capsys, extra, word):
    from vjm_pin.cli import main

    garbage = tmp_path / "g.csv"
    garbage.write_text("a,b\n1,2\n")
    extra = [e.format(npz=ur5_map[0], garbage=garbage) for e in extra]
    page = tmp_path / "x.html"
    code = main(["view", "ur5", *extra, "--html", str(page)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("vjm-pin: error:") and word in err[0]
    assert not page.exists()
