"""The wind example in a real library: the job writes the page and the three.js it imports, and headless Chromium,
served the folder over HTTP, loads a GLB with it and sways bark (per vertex) and leaves (per instance).

One palm built by `farm library add` (no Ray, 32 px textures); WebGL runs on SwiftShader (CPU).
"""
from __future__ import annotations

import base64
import functools
import http.server
import io
import json
import re
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from playwright import sync_api

from farm.library.job import add_asset
from farm.library.records import write_library_record
from farm.library.spec import parse_library_spec
from farm.library.wind_viewer import (THREE_FILES, VIEWER_THREE, WIND_PAGE, WindViewerError, three_source,
                                      three_version, wind_page_html, write_wind_viewer)
from farm.storage import Location
from required_tools import missing_tool

PROJECT = Path(__file__).resolve().parents[2]
SPEC = {"name": "wind", "seed": 1, "species": {"palm": 1}, "formats": ["glb"], "texture_size": 32,
        "impostor_tile": 16}
BACKGROUND = np.array([221, 232, 240])  # the page's clear colour, 0xdde8f0


def needs_local_three(test):
    """The test reads three.js from node_modules: skipped without it (failed with CI=true)."""
    @functools.wraps(test)
    def checked(*args, **kwargs):
        if not (PROJECT / "node_modules/three/package.json").is_file():
            missing_tool("three.js is not in node_modules: run `make node-env`")
        return test(*args, **kwargs)
    return checked


@pytest.fixture(scope="module")
def library(tmp_path_factory) -> Path:
    """A library folder holding one palm (treat as read-only)."""
    out = tmp_path_factory.mktemp("wind") / "library"
    write_library_record(Location.resolve(str(out)), parse_library_spec(SPEC))
    add_asset(str(out), "palm", 3)
    return out


@pytest.fixture(scope="module")
def glb(library) -> str:
    return json.loads((library / "catalog.json").read_text())[0]["files_json"]["glb"]


@needs_local_three
def test_the_library_holds_the_page_and_every_three_file_its_import_map_names(library, glb):
    page = (library / WIND_PAGE).read_text()
    imports = json.loads(re.search(r'<script type="importmap">(.*?)</script>', page).group(1))["imports"]
    assert imports == {"three": f"./{VIEWER_THREE}/build/three.module.js",
                       "three/addons/": f"./{VIEWER_THREE}/examples/jsm/"}
    for name in THREE_FILES:
        assert (library / VIEWER_THREE / name).read_bytes() == (PROJECT / "node_modules/three" / name).read_bytes()
    assert "unpkg" not in page and "{{" not in page
    assert f'href="{WIND_PAGE}?glb={glb}"' in (library / "index.html").read_text()


@needs_local_three
def test_writing_the_viewer_again_gives_the_same_bytes(library, tmp_path):
    shutil.copytree(library, tmp_path / "copy")
    write_wind_viewer(Location.resolve(str(tmp_path / "copy")))
    for name in [WIND_PAGE, *(f"{VIEWER_THREE}/{n}" for n in THREE_FILES)]:
        assert (tmp_path / "copy" / name).read_bytes() == (library / name).read_bytes()


def test_without_node_modules_the_page_imports_the_pinned_three_from_unpkg():
    version = json.loads((PROJECT / "package.json").read_text())["dependencies"]["three"]
    page = wind_page_html(local=False, version=three_version())
    assert f"https://unpkg.com/three@{version}/build/three.module.js" in page and VIEWER_THREE not in page


def test_a_node_modules_three_other_than_the_pin_is_rejected(tmp_path):
    (tmp_path / "node_modules/three").mkdir(parents=True)
    (tmp_path / "package.json").write_text(json.dumps({"dependencies": {"three": "0.187.0"}}))
    (tmp_path / "node_modules/three/package.json").write_text(json.dumps({"version": "0.170.0"}))
    with pytest.raises(WindViewerError, match="0.170.0.*0.187.0"):
        three_source(tmp_path)


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:
        pass


@pytest.fixture(scope="module")
def served(library):
    """The library folder on a plain local HTTP server (what `python -m http.server -d LIBRARY` does)."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler,
                                                                                  directory=str(library)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


@pytest.fixture(scope="module")
def wind_page(served, glb):
    """The example page with the palm loaded and its animation loop paused: yields (page, problems, requests)."""
    if shutil.which("chromium") is None:
        missing_tool("chromium is not installed: run `make browser-env`")
    if three_source() is None:
        missing_tool("three.js is not in node_modules: run `make node-env`")
    from farm.review.browser import launch_chromium

    with sync_api.sync_playwright() as playwright:
        browser = launch_chromium(playwright)
        page = browser.new_page(viewport={"width": 320, "height": 320})
        problems, requests = [], []
        page.on("pageerror", lambda error: problems.append(f"page error: {error}"))
        page.on("console", lambda message: problems.append(f"console: {message.text}")
                if message.type == "error" else None)
        page.on("request", lambda request: requests.append(request.url))
        page.goto(f"{served}/{WIND_PAGE}?glb={glb}")
        page.wait_for_function("window.__wind && (window.__wind.ready || window.__wind.error !== null)",
                               timeout=60_000)
        page.evaluate("window.__wind.pause()")
        yield page, problems, requests
        browser.close()


def frame(page, seconds: float, strength: float, part: str, layers=(1.0, 1.0, 1.0)) -> np.ndarray:
    """(320, 320, 3) int16 RGB: one frame at `seconds` with `strength`, showing "bark", "leaves" or "all"."""
    url = page.evaluate("""([seconds, strength, part, layers]) => {
        const wind = window.__wind;
        wind.setTime(seconds); wind.setStrength(strength); wind.setLayers(...layers); wind.show(part);
        return wind.frame();
    }""", [seconds, strength, part, list(layers)])
    image = Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB")
    return np.asarray(image, np.int16)


def changed_share(a: np.ndarray, b: np.ndarray) -> float:
    return float((np.abs(a - b).sum(axis=2) > 30).mean())


def covered_share(image: np.ndarray) -> float:
    return float((np.abs(image - BACKGROUND).sum(axis=2) > 30).mean())


def test_the_page_loads_the_glb_and_three_from_the_library_alone_without_errors(wind_page, served):
    page, problems, requests = wind_page
    parts = page.evaluate("window.__wind.parts")
    assert page.evaluate("window.__wind.error") is None
    assert parts["bark"] >= 1 and parts["leaves"] >= 1 and parts["leafInstances"] > 100
    assert {"_WIND", "_WIND_PIVOT"} <= set(parts["leafInstanceAttributes"])
    assert all(url.startswith(served) or url.startswith(("blob:", "data:")) for url in requests), requests
    assert problems == []


@pytest.mark.parametrize("part", ["bark", "leaves"])
def test_the_part_sways_between_two_times(wind_page, part):
    page, problems, _ = wind_page
    before, after = frame(page, 0.0, 1.0, part), frame(page, 1.7, 1.0, part)
    assert covered_share(before) > 0.01
    assert changed_share(before, after) > 0.1 * covered_share(before)
    assert problems == []


@pytest.mark.parametrize("part", ["bark", "leaves"])
def test_branch_swing_alone_moves_the_part_so_its_wind_attributes_are_read(wind_page, part):
    # Without trunk lean and leaf flutter, only the swing about each branch's pivot is left: it is zero unless
    # the shader reads a branch level >= 1 and a distance along the branch > 0 (per vertex on bark, per
    # instance on leaves; the card's own per-vertex _WIND is zero).
    page, problems, _ = wind_page
    swing_only = (0.0, 1.0, 0.0)
    before, after = frame(page, 0.0, 1.0, part, swing_only), frame(page, 1.7, 1.0, part, swing_only)
    assert changed_share(before, after) > 0.05 * covered_share(before)
    assert problems == []


def test_with_wind_strength_zero_nothing_moves(wind_page):
    page, problems, _ = wind_page
    before, after = frame(page, 0.0, 0.0, "all"), frame(page, 1.7, 0.0, "all")
    assert covered_share(before) > 0.02 and np.array_equal(before, after)
    assert problems == []
