"""The wind example in a real library: the job writes the page and the three.js it imports, and headless Chromium,
served the folder over HTTP, loads a GLB with it and sways bark (per vertex) and leaves (per instance), and draws
an octahedral impostor with its shader, leaning in the wind.

One palm built by `farm library add` (no Ray, 32 px textures) per library (crossed planes; octahedral impostor);
WebGL runs on SwiftShader (CPU).
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
from contextlib import contextmanager
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
from farm.dataset.storage import Location
from required_tools import missing_tool

PROJECT = Path(__file__).resolve().parents[2]
SPEC = {"name": "wind", "seed": 1, "species": {"palm": 1}, "formats": ["glb"], "texture_size": 32,
        "impostor_tile": 16}
OCTAHEDRAL_SPEC = {**SPEC, "impostor": "octahedral", "impostor_frames": 8, "impostor_tile": 48}
BACKGROUND = np.array([221, 232, 240])  # the page's clear colour, 0xdde8f0


def needs_local_three(test):
    """The test reads three.js from node_modules: skipped without it (failed with CI=true)."""
    @functools.wraps(test)
    def checked(*args, **kwargs):
        if not (PROJECT / "node_modules/three/package.json").is_file():
            missing_tool("three.js is not in node_modules: run `make node-env`")
        return test(*args, **kwargs)
    return checked


def one_palm_library(out: Path, spec: dict) -> Path:
    """A library folder of `spec` holding one palm."""
    write_library_record(Location.resolve(str(out)), parse_library_spec(spec))
    add_asset(str(out), "palm", 3)
    return out


def glb_path(library: Path) -> str:
    return json.loads((library / "catalog.json").read_text())[0]["files_json"]["glb"]


@pytest.fixture(scope="module")
def library(tmp_path_factory) -> Path:
    """A library folder holding one palm (treat as read-only)."""
    return one_palm_library(tmp_path_factory.mktemp("wind") / "library", SPEC)


@pytest.fixture(scope="module")
def glb(library) -> str:
    return glb_path(library)


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


@contextmanager
def serving(folder: Path):
    """The folder on a plain local HTTP server (what `python -m http.server -d LIBRARY` does): yields its URL."""
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_QuietHandler,
                                                                                  directory=str(folder)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture(scope="module")
def chromium():
    """Headless Chromium (one for the module: playwright's sync API runs one at a time)."""
    if shutil.which("chromium") is None:
        missing_tool("chromium is not installed: run `make browser-env`")
    if three_source() is None:
        missing_tool("three.js is not in node_modules: run `make node-env`")
    from farm.review.browser import launch_chromium

    with sync_api.sync_playwright() as playwright:
        browser = launch_chromium(playwright)
        yield browser
        browser.close()


@contextmanager
def opened_page(browser, address: str):
    """The example page at `address` loaded in a new tab, its animation loop paused: yields (page, problems,
    requests)."""
    page = browser.new_page(viewport={"width": 320, "height": 320})
    problems, requests = [], []
    page.on("pageerror", lambda error: problems.append(f"page error: {error}"))
    page.on("console", lambda message: problems.append(f"console: {message.text}")
            if message.type == "error" else None)
    page.on("request", lambda request: requests.append(request.url))
    page.goto(address)
    page.wait_for_function("window.__wind && (window.__wind.ready || window.__wind.error !== null)",
                           timeout=60_000)
    page.evaluate("window.__wind.pause()")
    try:
        yield page, problems, requests
    finally:
        page.close()


@pytest.fixture(scope="module")
def served(library):
    with serving(library) as address:
        yield address


@pytest.fixture(scope="module")
def wind_page(chromium, served, glb):
    """The example page with the palm loaded and its animation loop paused: yields (page, problems, requests)."""
    with opened_page(chromium, f"{served}/{WIND_PAGE}?glb={glb}") as opened:
        yield opened


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


@contextmanager
def palm_page(chromium, folder: Path, spec: dict):
    """The example page showing the palm of a new one-palm library of `spec` in `folder`: yields (page,
    problems)."""
    library = one_palm_library(folder / "library", spec)
    with serving(library) as address, \
            opened_page(chromium, f"{address}/{WIND_PAGE}?glb={glb_path(library)}") as opened:
        yield opened[:2]


@pytest.fixture(scope="module")
def octahedral_page(chromium, tmp_path_factory):
    """The example page showing a palm whose GLB carries an octahedral impostor: yields (page, problems)."""
    with palm_page(chromium, tmp_path_factory.mktemp("octahedral"), OCTAHEDRAL_SPEC) as opened:
        yield opened


def test_a_glb_with_crossed_planes_has_no_impostor_for_the_page_to_draw(wind_page):
    page, problems, _ = wind_page
    assert page.evaluate("window.__wind.parts.impostor") is None
    assert problems == []


def test_the_page_draws_the_octahedral_impostor_where_lod0_stands(octahedral_page):
    page, problems = octahedral_page
    assert page.evaluate("window.__wind.error") is None
    assert page.evaluate("window.__wind.parts.impostor") == {"frames": 8, "tile": 48}
    tree, impostor = frame(page, 0.0, 0.0, "all"), frame(page, 0.0, 0.0, "impostor")
    tree_mask, impostor_mask = (np.abs(image - BACKGROUND).sum(axis=2) > 30 for image in (tree, impostor))
    assert covered_share(impostor) > 0.01
    # The impostor's pixels are where LOD0's are (its frame is the same palm from nearly the same side).
    overlap = (tree_mask & impostor_mask).sum() / (tree_mask | impostor_mask).sum()
    assert overlap > 0.5, overlap
    assert problems == []


def test_the_octahedral_impostor_leans_in_the_wind_and_keeps_still_without_it(octahedral_page):
    page, problems = octahedral_page
    before, after = frame(page, 0.0, 1.0, "impostor"), frame(page, 1.7, 1.0, "impostor")
    assert changed_share(before, after) > 0.1 * covered_share(before)
    still_before, still_after = frame(page, 0.0, 0.0, "impostor"), frame(page, 1.7, 0.0, "impostor")
    assert np.array_equal(still_before, still_after)
    assert problems == []


def test_the_octahedral_impostor_turns_with_the_camera(octahedral_page):
    # Seen from above, the frames of the top of the hemisphere are drawn: another silhouette than from the side.
    page, problems = octahedral_page
    side = frame(page, 0.0, 0.0, "impostor")
    above = page.evaluate("""() => {
        const wind = window.__wind;
        wind.view(0.0, 80.0);
        const image = wind.frame();
        wind.view();
        return image;
    }""")
    top = np.asarray(Image.open(io.BytesIO(base64.b64decode(above.split(",", 1)[1]))).convert("RGB"), np.int16)
    assert covered_share(top) > 0.01 and changed_share(side, top) > 0.3 * covered_share(side)
    assert problems == []


SKELETAL_SPEC = {**OCTAHEDRAL_SPEC, "skeletal_wind": True, "wind_period_s": 4.0}


@pytest.fixture(scope="module")
def clip_page(chromium, tmp_path_factory):
    """The example page showing a palm with baked skeletal wind (a 4 s clip) and an octahedral impostor: yields
    (page, problems)."""
    with palm_page(chromium, tmp_path_factory.mktemp("skeletal"), SKELETAL_SPEC) as opened:
        yield opened


def test_the_page_plays_the_wind_clip_on_skinned_bark_with_instanced_leaves(clip_page):
    page, problems = clip_page
    parts = page.evaluate("window.__wind.parts")
    assert page.evaluate("window.__wind.error") is None
    assert parts["clip"]["name"] == "wind" and parts["clip"]["duration"] == pytest.approx(4.0)
    assert parts["skinned"] >= 1 and parts["leafInstances"] > 100
    assert problems == []


def test_the_clip_moves_the_tree_and_one_period_later_gives_the_same_image(clip_page):
    page, problems = clip_page
    start, later, looped = (frame(page, t, 1.0, "all") for t in (0.0, 1.3, 4.0))
    assert covered_share(start) > 0.02
    assert changed_share(start, later) > 0.05 * covered_share(start)
    assert np.array_equal(start, looped)
    leaves_start, leaves_later = frame(page, 0.0, 1.0, "leaves"), frame(page, 1.3, 1.0, "leaves")
    assert changed_share(leaves_start, leaves_later) > 0.05 * covered_share(leaves_start)
    assert problems == []


def test_the_clip_leans_the_impostor_whole_and_one_period_later_gives_the_same_image(clip_page):
    # The impostor's level node is outside the scene the tree's mixer plays on: the clip's lean of it plays on a
    # mixer of its own, and the shader's own lean (not periodic in the clip's period) is off.
    page, problems = clip_page
    assert page.evaluate("window.__wind.parts.impostor") == {"frames": 8, "tile": 48}
    start, later, looped = (frame(page, t, 1.0, "impostor") for t in (0.0, 1.3, 4.0))
    assert covered_share(start) > 0.01
    assert changed_share(start, later) > 0.05 * covered_share(start)
    assert np.array_equal(start, looped)
    rest_start, rest_later = frame(page, 0.0, 0.0, "impostor"), frame(page, 1.3, 0.0, "impostor")
    assert np.array_equal(rest_start, rest_later)  # the clip's weight 0: the rest pose
    assert problems == []
