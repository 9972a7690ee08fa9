"""Headless Chromium screenshots for the browser tests (Debian's ``chromium``)."""

from __future__ import annotations

import shutil
import subprocess


def chromium() -> str | None:
    """Path of a Chromium binary, or None (the browser tests then skip, saying so)."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def start_screenshot(browser: str, url: str, png, profile, budget_ms: int = 4000) -> subprocess.Popen:
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


def screenshot_frames(browser: str, page, frames, tmp_path) -> dict:
    """RGB arrays (600, 800, 3) of the exported ``page`` paused at each animation frame
    (``#frame=K``), taken by parallel Chromium processes; fails the test with Chromium's
    stderr when a screenshot is missing."""
    import numpy as np
    import pytest
    from PIL import Image

    shots = {k: tmp_path / f"frame{k}.png" for k in frames}
    procs = {
        k: start_screenshot(browser, f"{page.as_uri()}#frame={k}", png, tmp_path / f"profile{k}")
        for k, png in shots.items()
    }
    for k, p in procs.items():
        try:
            _, err = p.communicate(timeout=120)
        except subprocess.TimeoutExpired:
            p.kill()
            pytest.fail(f"chromium did not finish the screenshot of frame {k} in 120 s")
        assert shots[k].is_file(), f"no screenshot of frame {k}: {err.decode(errors='replace')[-2000:]}"
    return {k: np.asarray(Image.open(png).convert("RGB")) for k, png in shots.items()}
