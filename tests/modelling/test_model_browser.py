"""The modelling page in headless Chromium, one browser for the module: desktop mode driven by mouse events, and VR
mode driven through a stubbed `navigator.xr` whose two controllers follow scripted poses. Each draws strokes,
makes a lobe, draws a branch, paints, grows, undoes, saves, loads and sends to the library; the grown GLB passes
the Khronos validator, the reloaded session grows the same bytes, the library validates.

WebGL runs on SwiftShader (CPU). With TREEFARM_DOC_SCREENSHOTS=1 the test writes docs/images/modelling_*.png.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import httpx
import numpy as np
import pytest
from playwright import sync_api

from farm.dataset.storage import Location
from farm.library import parse_library_spec, validate_library
from farm.library.records import write_library_record
from farm.modelling.session import new_session, session_to_json
from farm.token_server import TOKEN_HEADER
from gltf_validator import assert_valid_glb
from required_tools import missing_tool

from model_site import model_server

if shutil.which("chromium") is None:
    missing_tool("chromium is not installed: run `make browser-env`", allow_module_level=True)

DOC_IMAGES = Path(__file__).resolve().parents[2] / "docs" / "images"
SCREENSHOTS = os.environ.get("TREEFARM_DOC_SCREENSHOTS") == "1"
VR_SCALE, VR_ROOT = 0.08, np.array([0.0, 0.0, -0.9])  # vr.js: the model root in the room

# The WebXR stand-in (tests/tools/fake_webxr.js), its eye 1.5 m up and 0.4 m behind the room's origin, looking 35
# degrees down at the model.
FAKE_XR = ("window.__xrEyeMatrix = [1,0,0,0, 0,0.819,-0.574,0, 0,0.574,0.819,0, 0,1.5,0.4,1];\n"
           + (Path(__file__).resolve().parents[1] / "tools" / "fake_webxr.js").read_text())


def loop(centre, radius: float, depth: float, n: int = 12) -> list:
    """A closed loop in the page's frame (Y up): centre (x, y) on a vertical plane at z = depth."""
    t = np.linspace(0, 2 * np.pi, n + 1)
    return [[centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a), depth] for a in t]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """A modelling server with a sessions folder and a small library (GLB and USD: the Blender outputs have their
    own tests in tests/library)."""
    root = tmp_path_factory.mktemp("model")
    library = root / "library"
    spec = parse_library_spec({"name": "modelled", "species": ["sc_round_maple"], "formats": ["glb", "usd"],
                               "texture_size": 64})
    write_library_record(Location.resolve(str(library)), spec)
    with model_server(out=root / "sessions", library=library) as (base, token, service):
        yield base, token, service, root


def open_page(chromium_browser, site, init_script: str | None = None):
    base, token, service, _ = site
    page = chromium_browser.new_page(viewport={"width": 960, "height": 580})
    problems = []
    page.on("pageerror", lambda error: problems.append(f"page error: {error}"))
    page.on("console", lambda message: problems.append(f"console: {message.text}")
            if message.type == "error" and "409" not in message.text else None)
    if init_script:
        page.add_init_script(init_script)
    page.goto(f"{base}/?token={token}")
    page.wait_for_function("window.modelApp && window.modelApp.state !== null", timeout=60_000)
    return page, problems


def wait_for_tree(page) -> None:
    """Until the tree of the session's current version is drawn (in VR, until it is in the scene)."""
    page.wait_for_function("window.modelApp.view.treeVersion === window.modelApp.version", timeout=60_000)


def wait_for_version(page, version: int) -> None:
    try:
        page.wait_for_function(f"window.modelApp.version >= {version}", timeout=30_000)
    except sync_api.TimeoutError:
        status = page.evaluate("[window.modelApp.version, document.getElementById('status').textContent]")
        raise AssertionError(f"the page did not reach version {version}: (version, status) = {status}") from None


def grown_glb(site) -> bytes:
    base, token, service, _ = site
    response = httpx.post(f"{base}/api/grow", json={"version": service.version}, headers={TOKEN_HEADER: token},
                          timeout=60)
    assert response.status_code == 200
    return response.content


def screenshot(page, name: str) -> None:
    if SCREENSHOTS:
        DOC_IMAGES.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(DOC_IMAGES / f"modelling_{name}.png"))


def drag(page, points) -> None:
    """Press the left button at the first point (Y-up world metres) on the drawing plane, move through the rest,
    release: mouse events at the points' screen positions."""
    pixels = page.evaluate("""async (points) => {
        const THREE = await import('three');
        const app = window.modelApp, camera = app.viewer.camera;
        const rect = app.viewer.renderer.domElement.getBoundingClientRect();
        return points.map((p) => {
          const v = new THREE.Vector3(...p).project(camera);
          return [rect.left + (v.x + 1) / 2 * rect.width, rect.top + (1 - v.y) / 2 * rect.height];
        });
    }""", [list(map(float, p)) for p in points])
    page.mouse.move(*pixels[0])
    page.mouse.down()
    for x, y in pixels[1:]:
        page.mouse.move(x, y)
    page.mouse.up()


def small_and_still(page) -> int:
    """A small tree (the test's pace on a CPU renderer) grown when asked, not after every edit; the version."""
    page.locator("#auto-grow").uncheck()
    version = page.evaluate("window.modelApp.version") + 1
    page.evaluate("window.modelApp.edit('growth', { parameters: { iterations: 12 } })")
    wait_for_version(page, version)
    return version


def grow(page) -> None:
    page.evaluate("window.modelApp.grow()")
    wait_for_tree(page)


def set_plane_depth(page, depth: float) -> None:
    page.locator("#plane-depth").fill(str(depth))


def test_desktop_mode_models_grows_saves_loads_and_sends_to_the_library(chromium_browser, site, tmp_path):
    base, token, service, root = site
    page, problems = open_page(chromium_browser, site)
    assert page.locator("#enter-vr").is_disabled()  # no WebXR in plain headless Chromium
    version = small_and_still(page)
    page.keyboard.press("s")
    for depth in (-2.0, 2.0):  # two closed strokes on the plane pushed back and forth: one lobe between them
        set_plane_depth(page, depth)
        drag(page, loop((0.0, 9.0), 3.0, depth))
        version += 1
        wait_for_version(page, version)
    assert len(service.history.present.strokes) == 2
    screenshot(page, "strokes")
    page.keyboard.press("l")
    version += 1
    wait_for_version(page, version)
    assert len(service.history.present.lobes) == 1 and service.history.present.strokes == ()
    # A third loop drawn inside the lobe joins it (only the strips next to it are built).
    page.keyboard.press("s")
    set_plane_depth(page, 0.0)
    drag(page, loop((0.0, 9.0), 3.3, 0.0))
    version += 1
    wait_for_version(page, version)
    page.keyboard.press("l")
    version += 1
    wait_for_version(page, version)
    assert len(service.history.present.lobes) == 1 and len(service.history.present.lobes[0].strokes) == 3
    screenshot(page, "lobe")
    # Shape: press on the lobe's surface where it faces the camera and pull it a metre up.
    page.keyboard.press("h")
    before = np.array(service.history.present.lobes[0].vertices)
    front = page.evaluate("""() => {
        const camera = window.modelApp.viewer.camera.position;
        const away = (p) => camera.distanceTo({ x: p[0], y: p[1], z: p[2] });
        return window.modelApp.state.lobes[0].vertices.reduce((a, b) => (away(a) <= away(b) ? a : b));
    }""")
    drag(page, [front, [front[0], front[1] + 0.5, front[2]], [front[0], front[1] + 1.0, front[2]]])
    version += 1
    wait_for_version(page, version)
    screenshot(page, "shape")
    moved = np.linalg.norm(np.array(service.history.present.lobes[0].vertices) - before, axis=1)
    assert 0.5 < moved.max() and (moved < 1e-9).sum() > len(moved) // 2  # the handle pulled, far vertices pinned
    page.keyboard.press("b")
    set_plane_depth(page, 0.0)
    drag(page, [[0.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.1, 4.0, 0.0], [0.2, 6.0, 0.0]])
    version += 1
    wait_for_version(page, version)
    drag(page, [[0.0, 3.0, 0.0], [1.0, 4.5, 0.0], [2.0, 6.5, 0.0]])
    version += 1
    wait_for_version(page, version)
    assert [b.parent for b in service.history.present.branches] == [-1, 0]
    screenshot(page, "branches")
    page.keyboard.press("p")
    drag(page, [[-1.0, 11.0, 0.0], [0.0, 11.5, 0.0], [1.0, 11.0, 0.0]])
    version += 1
    wait_for_version(page, version)
    assert len(service.history.present.markers) > 0
    grow(page)
    screenshot(page, "brush")
    glb = grown_glb(site)
    assert_valid_glb(glb, tmp_path, "desktop.glb")
    # Undo the brush stroke: the version rises, the markers go, the tree regrows.
    page.locator("#undo").click()
    version += 1
    wait_for_version(page, version)
    assert len(service.history.present.markers) == 0
    grow(page)
    screenshot(page, "grown")
    # Save, change, load: the session is the saved one again, and grows the same bytes.
    page.locator("#session-name").fill("desktop")
    page.locator("#save").click()
    page.wait_for_function("document.getElementById('status').textContent.startsWith('saved')")
    saved = (root / "sessions" / "desktop.json").read_text()
    undone_glb = grown_glb(site)
    page.locator("#redo").click()
    version += 1
    wait_for_version(page, version)
    page.locator("#load").click()
    version += 1
    wait_for_version(page, version)
    assert service.session_json() == saved and grown_glb(site) == undone_glb
    page.locator("#send").click()
    page.wait_for_function("document.getElementById('status').textContent.startsWith('sent to the library')",
                           timeout=120_000)
    catalog = json.loads((root / "library" / "catalog.json").read_text())
    assert [row["id"] for row in catalog if "hand-modelled" in row["tags"]] == [
        page.locator("#status").inner_text().split()[-1]]
    assert validate_library(str(root / "library")) == []
    assert problems == []
    # A refused edit: the message is in the page (and the browser logs the 400), and the session stays.
    page.keyboard.press("l")
    page.wait_for_function("document.getElementById('status').classList.contains('error')")
    assert "at least one" in page.locator("#status").inner_text() and service.version == version
    assert [p for p in problems if "status of 400" not in p] == []
    page.close()


def room_pose(position, target=None) -> list:
    """A column-major 4 x 4 controller pose at `position` (room metres, Y up), looking at `target` if given."""
    matrix = np.eye(4)
    if target is not None:
        forward = np.asarray(position, float) - np.asarray(target, float)  # three's -Z looks at the target
        z = forward / np.linalg.norm(forward)
        x = np.cross([0.0, 1.0, 0.0], z)
        x /= np.linalg.norm(x)
        matrix[:3, :3] = np.c_[x, np.cross(z, x), z]
    matrix[:3, 3] = position
    return matrix.T.ravel().tolist()


def to_room(model_points) -> np.ndarray:
    return np.asarray(model_points, float) * VR_SCALE + VR_ROOT


def press_menu(page, name: str) -> None:
    """Aim the right controller at a button of the left hand's menu and pull the trigger."""
    page.evaluate("""async (name) => {
        const THREE = await import('three');
        const vr = window.modelVR, menu = vr.menu, index = ['stroke', 'lobe', 'branch', 'brush', 'move', 'grow',
          'undo', 'redo', 'save', 'load', 'send', 'exit'].indexOf(name);
        const [x, y, w, h] = vr.buttonAt(index);
        const width = menu.geometry.parameters.width, height = menu.geometry.parameters.height;
        menu.updateMatrixWorld(true);
        const u = (x + w / 2) / 512 - 0.5, v = 0.5 - (y + h / 2) / 640;
        const local = (d) => new THREE.Vector3(u * width, v * height, d);
        const target = menu.localToWorld(local(0)), eye = menu.localToWorld(local(0.1));
        const pose = new THREE.Matrix4().lookAt(eye, target, new THREE.Vector3(0, 1, 0)).setPosition(eye);
        window.__xrPoses.right = new Float32Array(pose.elements);
        window.__xrStep(1);
        window.__xrPress('right', 'selectstart');
        window.__xrPress('right', 'selectend');
    }""", name)


def trace(page, room_points, button: str = "select") -> None:
    """Hold the right trigger (or squeeze) while the controller moves through room points, one frame each."""
    page.evaluate("""([points, button]) => {
        const pose = (p) => new Float32Array([1,0,0,0, 0,1,0,0, 0,0,1,0, p[0],p[1],p[2],1]);
        window.__xrPoses.right = pose(points[0]);
        window.__xrStep(1);
        window.__xrPress('right', button + 'start');
        for (const p of points.slice(1)) { window.__xrPoses.right = pose(p); window.__xrStep(1); }
        window.__xrPress('right', button + 'end');
    }""", [np.asarray(room_points, float).tolist(), button])


def test_vr_mode_models_with_scripted_controllers(chromium_browser, site, tmp_path):
    base, token, service, root = site
    fresh = httpx.post(f"{base}/api/load", content=session_to_json(new_session()), headers={TOKEN_HEADER: token})
    assert fresh.status_code == 200 and fresh.json()["lobes"] == []  # the desktop test's model set aside
    page, problems = open_page(chromium_browser, site, FAKE_XR)
    page.wait_for_function("!document.getElementById('enter-vr').disabled")
    page.locator("#enter-vr").click()
    page.wait_for_function("window.modelVR.state === 'presenting'")
    page.evaluate("window.__xrConnect(); window.__xrStep(2)")
    assert page.evaluate("window.modelVR.menu.parent === window.modelVR.hands.left")  # the menu rides the left hand
    version = small_and_still(page)
    press_menu(page, "stroke")
    assert page.evaluate("window.modelApp.tool") == "stroke"
    # Model space (Y up) -> room: the model root's scale and place (vr.js).
    for depth in (-2.0, 2.0):
        trace(page, to_room(loop((0.0, 9.0), 3.0, depth)))
        version += 1
        wait_for_version(page, version)
    stroke = service.history.present.strokes[-1]
    assert np.allclose(stroke[:, 1], -2.0, atol=0.05) and abs(stroke[:, 2].mean() - 9.0) < 0.5  # Z up in the session
    press_menu(page, "lobe")
    version += 1
    wait_for_version(page, version)
    # Squeeze at the lobe's widest point, away from any branch, and pull outwards: the surface follows the hand.
    before = np.array(service.history.present.lobes[0].vertices)
    widest = before[np.argmax(before[:, 0])]
    widest_page = np.array([widest[0], widest[2], -widest[1]])
    trace(page, to_room([widest_page, widest_page + [0.5, 0.0, 0.0], widest_page + [1.0, 0.0, 0.0]]), button="squeeze")
    version += 1
    wait_for_version(page, version)
    pulled = np.array(service.history.present.lobes[0].vertices)
    assert np.linalg.norm(pulled - before, axis=1).max() > 0.5 and pulled[:, 0].max() > before[:, 0].max() + 0.5
    press_menu(page, "branch")
    trace(page, to_room([[0.0, y, 0.0] for y in np.linspace(0, 6, 13)]))
    trace(page, to_room([[x, 3.0 + x, 0.0] for x in np.linspace(0, 2.5, 8)]))
    version += 2
    wait_for_version(page, version)
    assert len(service.history.present.lobes) == 1 and [b.parent for b in service.history.present.branches] == [-1, 0]
    # The right stick sets the brush; the left stick turns the model (eq. 4.1) by the angle it swept.
    press_menu(page, "brush")
    radius = float(page.locator("#brush-radius").input_value())
    page.evaluate("""() => {
        const pads = window.__xrSession.inputSources;
        pads[1].gamepad.axes[2] = 1; window.__xrStep(5); pads[1].gamepad.axes[2] = 0;
        pads[0].gamepad.axes[3] = -1; window.__xrStep(1);
        pads[0].gamepad.axes[3] = 0; pads[0].gamepad.axes[2] = 1; window.__xrStep(1);
        pads[0].gamepad.axes[2] = 0; window.__xrStep(1);
    }""")
    assert float(page.locator("#brush-radius").input_value()) > radius
    turn = page.evaluate("window.modelApp.view.root.rotation.y")
    assert abs(abs(turn) - np.pi / 2) < 1e-6
    page.evaluate("window.modelApp.view.root.rotation.y = 0")
    trace(page, to_room([[-1.0, 11.0, 0.0], [0.0, 11.5, 0.0], [1.0, 11.0, 0.0]]))
    version += 1
    wait_for_version(page, version)
    assert len(service.history.present.markers) > 0
    # Squeeze at the side branch's tip and pull: its subtree moves rigidly with the hand.
    tip = np.array(service.history.present.branches[1].points[-1])
    tip_page = np.array([tip[0], tip[2], -tip[1]])
    before = np.array(service.history.present.branches[1].points)
    trace(page, to_room([tip_page, tip_page + [0.0, 0.5, 0.0], tip_page + [0.0, 1.0, 0.0]]), button="squeeze")
    version += 1
    wait_for_version(page, version)
    after = np.array(service.history.present.branches[1].points)
    assert np.allclose(after - before, [0.0, 0.0, 1.0], atol=1e-6)  # page +Y is session +Z
    press_menu(page, "grow")
    page.evaluate("window.__xrStep(2)")
    wait_for_tree(page)
    page.evaluate("window.__xrPoses.right = new Float32Array([1,0,0,0, 0,1,0,0, 0,0,1,0, 0.3,0.75,-0.55,1]);"
                  "window.__xrStep(1)")  # the right hand, with the brush round it, beside the tree
    screenshot(page, "vr")
    assert_valid_glb(grown_glb(site), tmp_path, "vr.glb")
    press_menu(page, "undo")
    version += 1
    wait_for_version(page, version)
    assert np.allclose(np.array(service.history.present.branches[1].points), before)
    page.locator("#session-name").fill("headset")
    press_menu(page, "save")
    page.wait_for_function("document.getElementById('status').textContent.startsWith('saved')")
    saved = (root / "sessions" / "headset.json").read_text()
    press_menu(page, "redo")
    press_menu(page, "load")
    version += 2
    wait_for_version(page, version)
    assert service.session_json() == saved
    press_menu(page, "send")
    page.wait_for_function("document.getElementById('status').textContent.startsWith('sent to the library')",
                           timeout=120_000)
    assert validate_library(str(root / "library")) == []
    press_menu(page, "exit")
    page.wait_for_function("window.modelVR.state === 'ended'")
    page.close()
    assert problems == []
