"""The review page in headless Chromium: a tree drawn on the canvas, a keyboard verdict stored, VR entry and exit.

WebGL runs on SwiftShader (CPU). VR runs against a stubbed `navigator.xr` that plays one headset frame per call.
"""
from __future__ import annotations

import io
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from conftest import running_server
from required_tools import missing_tool

if shutil.which("chromium") is None:
    missing_tool("chromium is not installed: run `make browser-env`", allow_module_level=True)

# A WebXR device stand-in (shared with the modelling page's tests): frames played with __xrStep().
FAKE_XR = (Path(__file__).resolve().parents[1] / "tools" / "fake_webxr.js").read_text()
NO_XR = "Object.defineProperty(Navigator.prototype, 'xr', { get: () => undefined, configurable: true });"


@pytest.fixture(scope="module")
def site(review_dataset, tmp_path_factory):
    with running_server(review_dataset, tmp_path_factory.mktemp("browser") / "reviews.sqlite") as running:
        yield running


@pytest.fixture
def open_page(chromium_browser, site):
    """Opens the review page (with an optional init script); yields (page, problems, service)."""
    pages = []

    def opener(init_script: str | None = None, reviewer: str = "browser"):
        base, token, service = site
        page = chromium_browser.new_page(viewport={"width": 1100, "height": 700})
        problems = []
        page.on("pageerror", lambda error: problems.append(f"page error: {error}"))
        page.on("console", lambda message: problems.append(f"console: {message.text}")
                if message.type == "error" else None)
        if init_script:
            page.add_init_script(init_script)
        page.goto(f"{base}/?token={token}&reviewer={reviewer}")
        page.wait_for_function("window.firstTreeDrawnAt !== undefined", timeout=60_000)
        pages.append(page)
        return page, problems, service

    yield opener
    for page in pages:
        page.close()


def canvas_pixels(page) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.locator("#viewer canvas").screenshot())).convert("RGB"), np.int16)


def next_frames(page, n: int = 3) -> None:
    page.evaluate("""(n) => new Promise((done) => {
        const tick = () => (--n ? requestAnimationFrame(tick) : done());
        requestAnimationFrame(tick);
    })""", n)


def test_the_canvas_shows_the_first_tree(open_page):
    page, problems, _ = open_page()
    with_tree = canvas_pixels(page)
    page.evaluate("window.reviewViewer.model.visible = false; window.reviewViewer.overlay.visible = false")
    next_frames(page)
    without_tree = canvas_pixels(page)
    changed = np.abs(with_tree - without_tree).sum(axis=2) > 30
    assert with_tree.shape[0] > 100 and changed.mean() > 0.02  # the tree covers a visible part of the canvas
    assert without_tree.std() > 0 and problems == []


def test_a_keyboard_approve_is_stored_on_the_server_and_moves_to_the_next_tree(open_page):
    page, problems, service = open_page(reviewer="keyboard")
    first = page.evaluate("window.reviewApp.trees[0].tree_id")
    page.keyboard.press("a")
    page.wait_for_function("window.lastVerdict !== undefined && window.reviewApp.selected === 1")
    assert [(v["reviewer"], v["verdict"]) for v in service.store.verdicts(first)] == [("keyboard", "approve")]
    assert page.locator(".card").first.locator(".badge.approve").count() == 1 and problems == []


def test_vr_mode_lays_out_the_page_and_a_panel_press_stores_a_verdict(open_page):
    page, problems, service = open_page(FAKE_XR, reviewer="headset")
    button = page.locator("#enter-vr")
    page.wait_for_function("!document.getElementById('enter-vr').disabled")
    assert button.inner_text() == "Enter VR"
    button.click()
    page.wait_for_function("window.reviewVR.state === 'presenting' && window.reviewVR.treeGroups.every((g) => g.userData.hit)")
    assert page.evaluate("window.reviewApp.mode") == "vr" and page.evaluate("window.reviewVR.treeGroups.length") == 6
    page.evaluate("window.__xrStep(3)")  # headset frames: layout, rays and panel drawn through three's XR path
    # Point the first controller at the panel's Approve button and pull the trigger.
    tree_id = page.evaluate("""async () => {
        const THREE = await import('three');
        const vr = window.reviewVR, panel = vr.panel, controller = vr.controllers[0];
        const w = panel.geometry.parameters.width, h = panel.geometry.parameters.height;
        const target = panel.localToWorld(new THREE.Vector3((145 / 800 - 0.5) * w, (0.5 - 355 / 440) * h, 0));
        const eye = panel.localToWorld(new THREE.Vector3((145 / 800 - 0.5) * w, (0.5 - 355 / 440) * h, 0.4));
        // XR controllers take their matrix from the pose, not from position/quaternion.
        controller.matrix.lookAt(eye, target, new THREE.Vector3(0, 1, 0)).setPosition(eye);
        controller.updateMatrixWorld(true);
        vr.pick(controller);
        return vr.selected.userData.treeId;
    }""")
    page.wait_for_function("window.lastVerdict && window.lastVerdict.reviewer === 'headset'")
    assert {v["reviewer"]: v["verdict"] for v in service.store.verdicts(tree_id)}["headset"] == "approve"
    page.evaluate("window.__xrSession.end()")
    page.wait_for_function("window.reviewApp.mode === 'desktop' && window.reviewVR.state === 'ended'")
    assert problems == []


def test_without_webxr_the_page_stays_in_desktop_mode(open_page):
    page, problems, _ = open_page(NO_XR)
    button = page.locator("#enter-vr")
    assert button.is_disabled() and button.inner_text() == "VR unavailable"
    assert page.evaluate("window.reviewApp.mode") == "desktop" and problems == []
