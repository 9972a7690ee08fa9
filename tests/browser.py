"""Headless Chromium screenshots for the browser tests (Debian's ``chromium``)."""

from __future__ import annotations

import shutil
import subprocess


def chromium() -> str | None:
    """Path of a Chromium binary, or None (the browser tests then skip, saying so)."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def start_screenshot(
    browser: str, url: str, png, profile, budget_ms: int = 4000
) -> subprocess.Popen:
    """Start headless Chromium writing a screenshot of ``url`` to ``png`` (800×600).

    Software WebGL (swiftshader) and no background networking, so it runs offline."""
    return subprocess.Popen(
        [
            browser,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={profile}",
            f"--virtual-time-budget={budget_ms}",
            "--window-size=800,600",
            f"--screenshot={png}",
            url,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def screenshot_frames(browser: str, page, frames, tmp_path, hud: bool = False) -> dict:
    """RGB arrays (600, 800, 3) of the exported ``page`` paused at each animation frame
    (``#frame=K``), taken by parallel Chromium processes; fails the test with Chromium's
    stderr when a screenshot is missing. Without ``hud`` the page hides its labels, legend
    and controls (``#hud=0``), so that pixel counts see the scene only."""
    import numpy as np
    import pytest
    from PIL import Image

    shots = {k: tmp_path / f"frame{k}.png" for k in frames}
    procs = {
        k: start_screenshot(
            browser,
            f"{page.as_uri()}#frame={k}" + ("" if hud else "&hud=0"),
            png,
            tmp_path / f"profile{k}",
        )
        for k, png in shots.items()
    }
    try:
        for k, p in procs.items():
            try:
                _, err = p.communicate(timeout=120)
            except subprocess.TimeoutExpired:
                pytest.fail(f"chromium did not finish the screenshot of frame {k} in 120 s")
            assert shots[k].is_file(), (
                f"no screenshot of frame {k}: {err.decode(errors='replace')[-2000:]}"
            )
    finally:
        for p in procs.values():  # only the processes started here
            if p.poll() is None:
                p.kill()
                p.wait()
    return {k: np.asarray(Image.open(png).convert("RGB")) for k, png in shots.items()}


def screenshot_grid(browser: str, shots, tmp_path, cell=(480, 360), hud: bool = False) -> dict:
    """Like :func:`screenshot_frames`, with one Chromium process for several pages and frames:
    ``shots`` maps a key to ``(page, frame)``; a page of iframes (two per row, each ``cell``
    pixels, each ``page#frame=K``) is shot once and cut into one RGB array
    (cell[1], cell[0], 3) per key. Much cheaper than one browser per picture on a busy
    machine."""
    import numpy as np
    import pytest
    from PIL import Image

    items = list(shots.items())
    w, h = cell
    cols = 2 if len(items) > 1 else 1
    rows = (len(items) + cols - 1) // cols
    cells = "".join(
        f'<iframe src="{page.as_uri()}#frame={k}{"" if hud else "&hud=0"}" '
        f'style="position:absolute;left:{(i % cols) * w}px;top:{(i // cols) * h}px;'
        f'width:{w}px;height:{h}px;border:0"></iframe>'
        for i, (_, (page, k)) in enumerate(items)
    )
    grid = tmp_path / "grid.html"
    grid.write_text(
        f"<!DOCTYPE html><html><body style='margin:0'>{cells}</body></html>", encoding="utf-8"
    )
    png = tmp_path / "grid.png"
    args = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--use-gl=swiftshader",
        "--enable-unsafe-swiftshader",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile-grid'}",
        "--virtual-time-budget=4000",
        f"--window-size={cols * w},{rows * h}",
        f"--screenshot={png}",
        grid.as_uri(),
    ]
    p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        _, err = p.communicate(timeout=180)
    except subprocess.TimeoutExpired:
        pytest.fail("chromium did not finish the grid screenshot in 180 s")
    finally:
        if p.poll() is None:  # only the process started here
            p.kill()
            p.wait()
    assert png.is_file(), f"no grid screenshot: {err.decode(errors='replace')[-2000:]}"
    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape[:2] == (rows * h, cols * w), img.shape
    return {
        key: img[(i // cols) * h : (i // cols + 1) * h, (i % cols) * w : (i % cols + 1) * w].copy()
        for i, (key, _) in enumerate(items)
    }
