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
