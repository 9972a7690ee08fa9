"""Streamed maps: rows written as chunks finish, in pose order, never the whole map in memory."""

import csv
import json

import numpy as np
import pytest

from vjm_pin.analysis import maps
from vjm_pin.analysis.maps import CsvStream, MapSummary, run_map, sample_poses, stream_map
from vjm_pin.cli import main
from vjm_pin.exceptions import InputError, MapInterrupted
from vjm_pin.model.robots import build_robot

W = np.array([0.0, 0.0, -100.0, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def ur5():
    return build_robot("ur5").vm


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.reader(fh))


def test_streamed_csv_equals_the_map_written_at_the_end(ur5, tmp_path):
    names, poses = sample_poses(ur5, 30, seed=5)
    res = run_map(ur5, names, poses, W, backend="serial", chunk=4)
    res.to_csv(tmp_path / "whole.csv")
    summ = stream_map(ur5, names, poses, W, tmp_path / "s.csv", backend="local", workers=2, chunk=4)
    a, b = _rows(tmp_path / "whole.csv"), _rows(tmp_path / "s.csv")
    assert a[0] == b[0] and len(a) == len(b) == 31
    for ra, rb in zip(a[1:], b[1:]):
        assert ra[-1] == rb[-1]  # status
        np.testing.assert_array_equal(np.array(ra[:-1], float), np.array(rb[:-1], float))
    assert isinstance(summ, MapSummary) and summ.n_poses == 30 and summ.status_counts() == {"ok": 30}
    np.testing.assert_array_equal(summ.k_min, res.k_min)
    np.testing.assert_array_equal(summ.deflection_norm, np.linalg.norm(res.deflection[:, :3], axis=1))
    assert [p.name for p in tmp_path.iterdir()] == sorted(["whole.csv", "s.csv"]) or len(list(tmp_path.iterdir())) == 2


def test_memory_does_not_grow_with_the_number_of_poses(ur5, tmp_path, monkeypatch):
    """A mocked large run (chunks finishing out of order, as on a pool): the writer holds at
    most the chunks in flight, whatever N, and no per-pose rows are kept after writing."""
    import vjm_pin.analysis.map_backends as mb

    def fake_worker(text, names, wrench, gravity, method, loads, jit, csv_text, chunk):
        return [
            {"p0": np.zeros(3), "deflection": np.full(6, 1e-3), "k_along": 1.0, "k_min": 0.5, "stable": True, "status": "ok"}
            for _ in chunk
        ]

    def out_of_order(fn, args, chunks, report, **kw):  # pairs of chunks finish swapped
        k = 0
        while k < len(chunks):
            group = list(range(k, min(k + 2, len(chunks))))
            for j in reversed(group):
                report(j, fn(*args, chunks[j]))
            k += 2

    monkeypatch.setattr(maps, "_chunk_worker", fake_worker)
    monkeypatch.setattr(mb, "run_chunks", out_of_order)
    held = []
    orig_add = CsvStream.add

    def spy(self, start, rows):
        orig_add(self, start, rows)
        held.append(sum(len(r) for r in self.pending.values()))

    monkeypatch.setattr(CsvStream, "add", spy)
    names = maps.mapped_joints(ur5)
    for n in (200, 20_000):
        held.clear()
        poses = np.zeros((n, len(names)))
        summ = stream_map(ur5, names, poses, W, tmp_path / f"big{n}.csv", backend="serial", chunk=50)
        assert summ.n_poses == n
        assert max(held) <= 50  # one chunk waits for its predecessor, never more
        with open(tmp_path / f"big{n}.csv") as fh:
            assert sum(1 for _ in fh) == n + 1


def test_interrupt_keeps_finished_poses_and_errors_leave_no_file(ur5, tmp_path, monkeypatch):
    import vjm_pin.analysis.map_backends as mb

    names, poses = sample_poses(ur5, 12, seed=2)

    def interrupted(fn, args, chunks, report, **kw):
        report(1, fn(*args, chunks[1]))  # chunk 0 never finishes
        raise KeyboardInterrupt

    monkeypatch.setattr(mb, "run_chunks", interrupted)
    target = tmp_path / "m.csv"
    with pytest.raises(MapInterrupted) as e:
        stream_map(ur5, names, poses, W, target, backend="serial", chunk=4)
    assert e.value.result.n_poses == 4 and len(_rows(target)) == 5
    np.testing.assert_array_equal(np.array([r[: len(names)] for r in _rows(target)[1:]], float), poses[4:8])

    target.write_text("keep me")

    def nothing(fn, args, chunks, report, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(mb, "run_chunks", nothing)
    with pytest.raises(MapInterrupted):
        stream_map(ur5, names, poses, W, target, backend="serial", chunk=4)
    assert target.read_text() == "keep me"

    def broken(fn, args, chunks, report, **kw):
        report(0, fn(*args, chunks[0]))
        raise RuntimeError("worker died")

    monkeypatch.setattr(mb, "run_chunks", broken)
    with pytest.raises(RuntimeError):
        stream_map(ur5, names, poses, W, target, backend="serial", chunk=4)
    assert target.read_text() == "keep me" and sorted(p.name for p in tmp_path.iterdir()) == ["m.csv"]
    with pytest.raises(InputError, match="must end in .csv"):
        stream_map(ur5, names, poses, W, tmp_path / "m.npz")


def test_cli_streams_csv_and_plots_with_a_floor(tmp_path, capsys):
    out = tmp_path / "m.csv"
    assert main(["map", "ur5", "--samples", "12", "--backend", "serial", "--out", str(out), "--json"]) == 0
    cap = capsys.readouterr()
    body = json.loads(cap.out)
    data = body.get("data", body)
    assert data["poses"] == 12 and len(_rows(out)) == 13
    assert "12 poses in" in cap.err  # no terminal: a one-line summary instead of a bar
    png = tmp_path / "m.png"
    grid = ["--grid", "shoulder_lift_joint=-2:-0.5:3", "elbow_joint=0.5:2:3"]
    for floor in ("0", "none", "0.3"):
        assert main(["map", "ur5", *grid, "--backend", "serial", "--plot", str(png), "--floor", floor, "--quiet"]) == 0
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert capsys.readouterr().err == ""
    assert main(["map", "ur5", "--samples", "3", "--plot", str(png), "--floor", "high"]) == 2
    assert "--floor" in capsys.readouterr().err


def test_csv_text_is_the_csv_modules(ur5, tmp_path):
    """The rows are formatted in bulk (maps._csv_lines): the same text as csv.writer on the
    per-field values (repr of the floats, 0/1, the status)."""
    import io

    names, poses = sample_poses(ur5, 7, seed=8)
    res = run_map(ur5, names, poses, W, backend="serial")
    res.to_csv(tmp_path / "m.csv")
    buf = io.StringIO(newline="")
    wr = csv.writer(buf)
    cols = res.columns()
    wr.writerow(list(cols))
    for i in range(len(poses)):
        wr.writerow([maps._csv_value(c[i]) for c in cols.values()])
    assert (tmp_path / "m.csv").read_bytes() == buf.getvalue().encode()
