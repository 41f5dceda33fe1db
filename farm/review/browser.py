"""Headless Chromium for checking the review page: Debian's chromium driven by playwright, WebGL on the CPU.

Used by the browser tests and benchmarks/bench_review.py; `make browser-env` installs the browser.
"""
from __future__ import annotations

import shutil

from .store import ReviewError

__all__ = ["CHROMIUM", "CHROMIUM_ARGS", "launch_chromium", "chromium_path"]

CHROMIUM = "/usr/bin/chromium"
# SwiftShader renders WebGL on the CPU (no GPU here); the rest keeps a headless run quiet and offline.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def chromium_path() -> str:
    path = shutil.which("chromium") or (CHROMIUM if shutil.which(CHROMIUM) else None)
    if path is None:
        raise ReviewError("chromium is not installed: run `make browser-env` (apt-get install chromium)")
    return path


def launch_chromium(playwright):
    """A headless Chromium browser from a started `playwright.sync_api.sync_playwright()`."""
    return playwright.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS, headless=True)
