"""The command line's contract with the shell (issue 11).

- A bad input is one line ``vjm-pin: error: ...`` on stderr naming the problem, exit 2, no
  traceback, no output file created, the input files untouched (bytes and mtime). Output
  paths are checked before the work starts.
- Negative numbers in every float form are values (``-1e-3``, ``-.5``, ``-inf``).
- ``--version``; a closed stdout ends the run quietly; Ctrl-C anywhere: one line, exit 130.

Most rows run in process (``main([...])``); a few run the installed ``vjm-pin`` in a
subprocess to check real exit codes, pipes and signals.
"""

from __future__ import annotations

import json
import math
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vjm_pin.cli import NEGATIVE_NUMBER, build_parser, main
from vjm_pin.model.registry import bundled_models

UNWRITABLE = "/proc/1"  # not writable even for root (procfs refuses new files)
CURVE = shlex.split("curve paper-c-s --direction -1 0 0 --max-deflection 0.01 --steps 2")
VIEW = shlex.split("view paper-c-s --deflection -0.0001 0 0")
MAP = shlex.split("map ur5 --samples 2 --no-progress --backend serial")


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A folder with input files of every kind; the test runs inside it."""
    shutil.copy(bundled_models()["paper-c-s"], tmp_path / "mine.urdf")
    (tmp_path / "spec.yaml").write_text("actuators: {}\n")
    (tmp_path / "bin.urdf").write_bytes(b"\x00\x01<robot\xff\xfe")
    (tmp_path / "text.urdf").write_text("hello\n")
    (tmp_path / "empty.yaml").write_text("")
    (tmp_path / "plot.png").mkdir()  # a folder with a plot's name
    (tmp_path / "link.html").symlink_to(tmp_path / "mine.urdf")  # an alias of the input
    monkeypatch.chdir(tmp_path)
    return tmp_path


def snapshot(folder: Path) -> dict:
    """Every entry under ``folder``: name -> (bytes, mtime_ns) for files, 'dir' for folders."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            out[str(p)] = ("link", os.readlink(p))
        elif p.is_dir():
            out[str(p)] = "dir"
        else:
            st = p.stat()
            out[str(p)] = (p.read_bytes(), st.st_mtime_ns)
    return out


def assert_one_line_error(err: str, fragment: str) -> None:
    lines = err.splitlines()
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    assert lines[0].startswith("vjm-pin: error: "), err
    assert fragment in lines[0], err


# (command line, fragment of the one-line message); output paths first, all refused before
# any work. In a line, {CURVE}, {VIEW} and {MAP} stand for the short runs above, {C}, {V}
# and {M} for their options after the model, {RO} for a folder not writable even for root.
BAD_LINES = [
    # --- output paths: missing folder, folder not writable, unknown extension, a folder, an
    #     empty name, an input file (directly or through a symlink)
    ("{CURVE} --plot nodir/x.png", "folder 'nodir' does not exist"),
    ("{CURVE} --plot {RO}/x.png", "is not writable"),
    ("{CURVE} --plot x.txt", "unknown extension '.txt'"),
    ("{CURVE} --plot plot.png", "is a folder"),
    ("{CURVE} --plot ''", "empty file name"),
    ("curve mine.urdf {C} --plot mine.urdf", "is the input file"),
    ("curve orthoglide-q0 {C} --plot nodir/x.png", "does not exist"),
    ("{VIEW} --html nodir/x.html", "folder 'nodir' does not exist"),
    ("{VIEW} --html {RO}/x.html", "is not writable"),
    ("{VIEW} --html x.png", "unknown extension '.png'"),
    ("{VIEW} --html ''", "empty file name"),
    ("view mine.urdf {V} --html mine.urdf", "is the input file 'mine.urdf'"),
    ("view mine.urdf {V} --html link.html", "is the input file"),
    ("view ur5 --springs spec.yaml {V} --html spec.yaml", "is the input file 'spec.yaml'"),
    ("demo --out {RO}/demo", "is not writable"),
    ("demo --out mine.urdf", "is a file, not a folder"),
    ("demo --out mine.urdf/sub", "is a file, not a folder"),
    ("demo --out ''", "empty folder name"),
    ("{MAP} --out nodir/x.csv", "folder 'nodir' does not exist"),
    ("{MAP} --out {RO}/x.csv", "is not writable"),
    ("{MAP} --out x.txt", "unknown extension '.txt'"),
    ("{MAP} --plot nodir/x.png", "folder 'nodir' does not exist"),
    ("{MAP} --plot x.csv", "unknown extension '.csv'"),
    ("map mine.urdf {M} --out mine.urdf", "is the input file"),
    # --- models
    ("analyze nosuch.urdf", "nosuch.urdf"),
    ("analyze paper-c-x", "did you mean paper-c-z"),
    ("analyze paper-c-x", "see 'vjm-pin models'"),
    ("analyze .", "is a folder"),
    ("analyze bin.urdf", "bin.urdf"),
    ("analyze text.urdf", "malformed XML"),
    ("analyze ur5 --springs nosuch.yaml", "nosuch.yaml"),
    ("analyze ur5 --frame nosuch", "unknown frame 'nosuch'"),
    ("analyze ur5 --q nosuch=1", "unknown joint 'nosuch'"),
    ("analyze ur5 --q shoulder_pan_joint=abc", "'abc' is not a number"),
    ("analyze ur5 --q shoulder_pan_joint", "NAME=VALUE"),
    ("curve ur5 {C} --subdivide 2", "not to the robot 'ur5'"),
    # --- numbers
    ("analyze paper-c-s --deflection 1 2", "needs 3 or 6 numbers, got 2"),
    ("analyze paper-c-s --deflection nan 0 0", "NaN or infinite"),
    ("analyze paper-c-s --deflection -inf 0 0", "NaN or infinite"),
    ("analyze paper-c-s --deflection abc 0 0", "invalid float value: 'abc'"),
    ("analyze paper-c-s --deflection", "expected at least one argument"),
    ("analyze paper-c-s --payload -1", "payload"),
    ("analyze paper-c-s --payload nan", "--payload must be a finite non-negative mass"),
    # --- dead loads (--load FRAME FX FY FZ [MX MY MZ]) and closed mechanisms
    ("analyze paper-c-s --load ennd 0 0 -1", "unknown frame 'ennd' in model 'paper-c-s'; did you mean 'end'?"),
    ("analyze portal-frame --load top_lft 0 0 -1", "did you mean 'top_left'"),
    ("analyze paper-c-s --load end 1 0", "expected FRAME FX FY FZ [MX MY MZ]"),
    ("analyze paper-c-s --load end 1 0 0 1", "expected FRAME FX FY FZ [MX MY MZ]"),
    ("analyze paper-c-s --load end 1 0 abc", "'abc' is not a number"),
    ("analyze paper-c-s --load end 1 0 inf", "'inf' is not finite"),
    ("analyze paper-c-s --load", "expected at least one argument"),
    ("{CURVE} --load nosuch 0 0 -1", "unknown frame 'nosuch'"),
    ("{CURVE} --load end 0 0", "expected FRAME FX FY FZ"),
    ("analyze portal-frame --method eq31", "invalid choice: 'eq31'"),
    ("{CURVE} --refine-tol 1e300", "--refine-tol: must be from 1e-10 to 0.1"),
    ("analyze portal-frame --subdivide 2", "not available for models with loop closures"),
    ("curve portal-frame {C} --subdivide 2", "not available for models with loop closures"),
    ("analyze portal-frame --wrench 1 0 0 --load top 0 0 -1 0 0", "expected FRAME FX FY FZ"),
    ("analyze portal-frame --wrench 0 1 0", "not in the task"),
    ("analyze paper-c-s --subdivide 0", "--subdivide: must be an integer from 1 to"),
    ("analyze paper-c-s --subdivide 1000", "--subdivide: must be an integer from 1 to"),
    ("curve paper-c-s --direction 0 0 0 --max-deflection 0.01", "direction"),
    ("curve paper-c-s --direction 1 0 --max-deflection 0.01", "needs 3 or 6 numbers"),
    ("curve paper-c-s --direction -1 0 0 --max-deflection 0", "--max-deflection: must be a finite"),
    (
        "curve paper-c-s --direction -1 0 0 --max-deflection -1e-2",
        "--max-deflection: must be a fin",
    ),
    (
        "curve paper-c-s --direction -1 0 0 --max-deflection nan",
        "--max-deflection: must be a finite",
    ),
    (
        "curve paper-c-s --direction -1 0 0 --max-deflection 0.01 --steps 0",
        "--steps: must be an integer at least 1",
    ),
    (
        "curve paper-c-s --direction -1 0 0 --max-deflection 0.01 --steps -1",
        "--steps: must be an integer at least 1",
    ),
    (
        "curve paper-c-s --direction -1 0 0 --max-deflection 0.01 --steps 1e3",
        "--steps: expected an integer",
    ),
    ("{CURVE} --refine-tol -1", "--refine-tol: must be a finite number > 0"),
    ("{VIEW} --scale 0", "--scale: must be a finite number > 0"),
    ("{VIEW} --direction 1 0 0", "--direction applies with --curve only"),
    ("view paper-c-s --curve --direction -1 0 0 --max-deflection 0.01 --steps 1", "at least 2"),
    ("map ur5 --samples 0", "--samples"),
    # --- usage
    ("nosuch", "invalid choice: 'nosuch'"),
    ("models --nosuch", "unrecognized arguments: --nosuch"),
    ("analyze paper-c-s --deflection 1 0 0 --wrench 1 0 0", "not allowed with"),
]


def _argv(line: str) -> list[str]:
    runs = {"CURVE": CURVE, "VIEW": VIEW, "MAP": MAP}
    fields = {name: shlex.join(argv) for name, argv in runs.items()}
    fields.update({name[0]: shlex.join(argv[2:]) for name, argv in runs.items()})
    return shlex.split(line.format(RO=UNWRITABLE, **fields))


BAD = [(_argv(line), fragment) for line, fragment in BAD_LINES]


@pytest.mark.parametrize("argv, fragment", BAD, ids=[" ".join(a)[:80] for a, _ in BAD])
def test_bad_input_is_one_line_exit_2_and_touches_nothing(argv, fragment, work, capsys):
    before = snapshot(work)
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert_one_line_error(captured.err, fragment)
    assert snapshot(work) == before  # no output created, inputs unchanged (bytes and mtime)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (CURVE + ["--plot", "nodir/x.png"], "folder 'nodir' does not exist"),
        (["view", "mine.urdf", *VIEW[2:], "--html", "mine.urdf"], "is the input file"),
    ],
)
def test_bad_input_in_a_real_process(argv, fragment, work):
    before = snapshot(work)
    r = subprocess.run(["vjm-pin", *argv], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 2, r.stderr
    assert_one_line_error(r.stderr, fragment)
    assert r.stdout == ""
    assert snapshot(work) == before


# ----------------------------------------------------------------------------- outputs
def test_output_checks_run_before_the_work(work, monkeypatch, capsys):
    """A bad --plot is reported without tracing anything."""
    import vjm_pin.analysis.curve

    def boom(*a, **k):
        raise AssertionError("the curve was traced before the output path was checked")

    monkeypatch.setattr(vjm_pin.analysis.curve, "trace_curve", boom)
    assert main(CURVE + ["--plot", "nodir/x.png"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_existing_plot_is_replaced_and_no_temporary_file_remains(work, capsys):
    out = work / "c.pdf"
    out.write_bytes(b"old")
    assert main(CURVE + ["--plot", "c.pdf"]) == 0
    data = out.read_bytes()
    assert data.startswith(b"%PDF") and data != b"old"  # format from the extension
    assert not [p for p in work.iterdir() if p.name.startswith(".c.")]  # no temporary left


def test_interrupted_plot_keeps_the_previous_file(work, monkeypatch):
    """savefig interrupted half-way: the old file stays, no partial or temporary file."""
    from matplotlib.figure import Figure

    from vjm_pin.viz.plots import save_curve_plot
    from vjm_pin.model.registry import resolve_model
    from vjm_pin.analysis.curve import trace_curve

    curve = trace_curve(resolve_model("paper-c-s"), [-1, 0, 0], 0.002, 2)
    out = work / "c.png"
    out.write_bytes(b"previous plot")
    names = sorted(p.name for p in work.iterdir())

    def half_then_interrupt(self, fname, **kw):
        Path(fname).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", half_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        save_curve_plot(curve, out)
    assert out.read_bytes() == b"previous plot"
    assert sorted(p.name for p in work.iterdir()) == names


def test_interrupted_html_page_leaves_no_file(work, monkeypatch):
    from vjm_pin import outputs

    real = outputs.atomic_output

    def interrupted(path, mode=None):
        cm = real(path, mode)
        fh = cm.__enter__()
        fh.write("<html>half")
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            cm.__exit__(*sys.exc_info())
            raise

    monkeypatch.setattr(outputs, "atomic_output", interrupted)
    assert main(VIEW + ["--html", "page.html"]) == 130
    assert not [p for p in work.iterdir() if "page" in p.name]


def test_demo_creates_its_folder_only_after_the_checks(work, capsys, monkeypatch):
    """--out may name a folder to create; a failed check creates nothing."""
    assert main(["demo", "--out", "mine.urdf/sub"]) == 2
    assert not (work / "mine.urdf").is_dir()


# ----------------------------------------------------------------------------- numbers
@pytest.mark.parametrize(
    "token",
    ["-1", "-1.5", "-.5", "-1.", "-1e-3", "-1E+2", "-2.5e3", "-1_000", "-inf", "-Infinity", "-nan"],
)
def test_negative_number_forms_are_values(token):
    assert NEGATIVE_NUMBER.match(token)
    float(token)  # every form the matcher accepts is a float


@pytest.mark.parametrize("token", ["-h", "--help", "-e5", "-1e", "-.", "-", "--1", "-x1", "-1e-3x"])
def test_options_are_not_numbers(token):
    assert not NEGATIVE_NUMBER.match(token)


def test_every_parser_knows_exponent_negatives():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    parsers = [parser, *sub.choices.values()]
    assert all(p._negative_number_matcher is NEGATIVE_NUMBER for p in parsers)


@pytest.mark.parametrize(
    "argv, attr, value",
    [
        (["analyze", "paper-c-s", "--deflection", "-1e-3", "0", "0"], "deflection", [-1e-3, 0, 0]),
        (["analyze", "paper-c-s", "--wrench", "0", "0", "-1e2"], "wrench", [0, 0, -100.0]),
        (
            ["analyze", "paper-c-s", "--deflection", "-.5", "-1.", "-2E-1"],
            "deflection",
            [-0.5, -1.0, -0.2],
        ),
        (
            ["curve", "paper-c-s", "--direction", "-1", "0", "0", "--max-deflection", "1e-2"],
            "direction",
            [-1, 0, 0],
        ),
        (
            ["curve", "paper-c-s", "--direction", "-1e0", "-0", "0", "--max-deflection", "1e-2"],
            "direction",
            [-1, 0, 0],
        ),
        (
            [
                "view",
                "paper-c-s",
                "--curve",
                "--direction",
                "-1e-1",
                "0",
                "0",
                "--max-deflection",
                "1",
            ],
            "direction",
            [-0.1, 0, 0],
        ),
        (["view", "paper-c-s", "--wrench", "-1e1", "0", "0"], "wrench", [-10.0, 0, 0]),
        (["map", "ur5", "--samples", "2", "--wrench", "0", "0", "-1e2"], "wrench", [0, 0, -100.0]),
        (
            ["map", "ur5", "--grid", "shoulder_pan_joint=-1:1:3", "--wrench", "-1e1", "0", "0"],
            "wrench",
            [-10, 0, 0],
        ),
    ],
)
def test_negative_numbers_parse_in_every_command(argv, attr, value):
    args = build_parser().parse_args(argv)
    assert getattr(args, attr) == pytest.approx(value)


@pytest.mark.parametrize("command", ["analyze", "curve"])
def test_load_takes_negative_numbers_and_repeats(command):
    """--load FRAME FX FY FZ [MX MY MZ]: negative numbers in every float form are values, the
    option repeats, 3 or 6 numbers each (Load tuples in order, world axes)."""
    from vjm_pin.cli.common import loads_from_args

    extra = ["--direction", "-1", "0", "0", "--max-deflection", "1e-2"] if command == "curve" else []
    args = build_parser().parse_args(
        [command, "paper-c-s", *extra, "--load", "link1", "-1e-3", "-.5", "0",
         "--load", "end", "1", "-2E1", "3", "-1", "-0", "2.5"]
    )
    la, lb = loads_from_args(args)
    assert (la.frame, lb.frame) == ("link1", "end")
    assert la.wrench == pytest.approx([-1e-3, -0.5, 0, 0, 0, 0])
    assert lb.wrench == pytest.approx([1, -20, 3, -1, 0, 2.5])


def test_negative_exponent_deflection_runs(capsys):
    assert main(["analyze", "paper-c-s", "--deflection", "-1e-4", "0", "0", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["deflection"][0] == pytest.approx(-1e-4, rel=1e-6)


def test_direction_scale_does_not_matter(capsys):
    """Only the direction of --direction counts: 1e308 1e308 (its norm overflows) and 1e-320
    (subnormal) are the directions [1, 1, 0] and [1, 0, 0]."""
    from vjm_pin.cli.common import direction_vector

    d = direction_vector(["1e308", "1e308", "0"], "--direction")
    assert d[:3] == pytest.approx([1, 1, 0]) and all(math.isfinite(v) for v in d)
    assert direction_vector(["-1e-320", "0", "0"], "--direction")[:3] == pytest.approx([-1, 0, 0])


# ----------------------------------------------------------------------------- version, pipes
def test_version(capsys):
    from importlib import metadata

    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    assert capsys.readouterr().out.strip() == f"vjm-pin {metadata.version('vjm_pin')}"


def test_closed_stdout_is_quiet(tmp_path):
    """The reader closes the pipe before the first line is written: exit 0, empty stderr."""
    p = subprocess.Popen(["vjm-pin", "models"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=60) == 0, err
    assert err == ""


def test_head_of_models_is_quiet():
    r = subprocess.run(
        ["bash", "-c", "set -o pipefail; vjm-pin models | head -1"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert r.stderr == "" and r.stdout.startswith("bundled models")


# ----------------------------------------------------------------------------- Ctrl-C
def test_ctrl_c_in_a_command_is_one_line_130(monkeypatch, capsys):
    from vjm_pin.cli import models

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(models, "run", interrupted)
    assert main(["models"]) == 130
    err = capsys.readouterr().err
    assert err == "vjm-pin: interrupted\n"


def test_ctrl_c_while_building_the_parser(monkeypatch, capsys):
    import importlib

    real = importlib.import_module

    def interrupted(name, *a, **k):
        if name.startswith("vjm_pin.cli."):
            raise KeyboardInterrupt
        return real(name, *a, **k)

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert main(["models"]) == 130
    assert capsys.readouterr().err == "vjm-pin: interrupted\n"


def test_ctrl_c_turned_into_another_error_is_still_an_interruption(monkeypatch, capsys):
    """A library may catch the KeyboardInterrupt and raise something else (pydantic-core
    does during an import); the SIGINT record of main() still reports an interruption."""
    from vjm_pin.cli import models

    def wraps_the_interrupt(args):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs here
        except KeyboardInterrupt:
            raise RuntimeError("schema build failed") from None
        raise AssertionError("SIGINT was not delivered")

    monkeypatch.setattr(models, "run", wraps_the_interrupt)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert main(["models"]) == 130
    finally:
        signal.signal(signal.SIGINT, previous)
    assert capsys.readouterr().err == "vjm-pin: interrupted\n"
    assert signal.getsignal(signal.SIGINT) is previous  # main restored the handler


def test_an_error_without_sigint_is_not_hidden(monkeypatch):
    from vjm_pin.cli import models

    def bug(args):
        raise RuntimeError("a bug")

    monkeypatch.setattr(models, "run", bug)
    with pytest.raises(RuntimeError, match="a bug"):
        main(["models"])


def _wait_for_library(pid: int, timeout: float = 60.0) -> None:
    """Until the process has mapped Pinocchio (its imports are done, the work starts)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            if "pinocchio" in Path(f"/proc/{pid}/maps").read_text():
                return
        except OSError:
            return
        time.sleep(0.05)


def test_ctrl_c_during_a_long_curve(tmp_path):
    """SIGINT while a 100000-step curve is traced: exit 130, one line, no plot, no temporary."""
    argv = ["vjm-pin", *CURVE[:8], "--steps", "100000", "--plot", "long.png"]
    p = subprocess.Popen(
        argv, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    _wait_for_library(p.pid)
    time.sleep(1.0)
    assert p.poll() is None, p.communicate()[1]  # still working when interrupted
    p.send_signal(signal.SIGINT)
    try:
        _, err = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()
        raise
    assert p.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "vjm-pin: interrupted", err
    assert list(tmp_path.iterdir()) == []
