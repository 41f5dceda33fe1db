"""The modelling server: the token guard, path safety, body limits and a taken port as for `farm review`; the
JSON API's axes, refused edits, grow versions (overtaken requests dropped), save and load, and HTTPS."""
from __future__ import annotations

import http.client
import json
import re
import socket
import ssl
import subprocess
import sys
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import numpy as np
import pytest

import farm.modelling.service as service_module
from farm.cli import main
from farm.modelling.certificate import certificate_fingerprint, self_signed_certificate
from farm.modelling.server import MAX_EDIT_BYTES
from farm.modelling.service import Overtaken
from farm.token_server import TOKEN_HEADER

from model_site import model_server, ring


def y_up(points) -> list:
    """Z-up points as the page sends them (three.js, Y up): (x, z, -y)."""
    return [[x, z, -y] for x, y, z in np.asarray(points, float)]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    with model_server(out=tmp_path_factory.mktemp("sessions")) as running:
        yield running


def client(base: str, token: str | None) -> httpx.Client:
    return httpx.Client(base_url=base, headers={TOKEN_HEADER: token} if token else {}, timeout=60)


@pytest.mark.parametrize("method, path", [("GET", "/"), ("GET", "/api/version"), ("POST", "/api/stroke"),
                                          ("POST", "/api/grow"),
                                          ("GET", "/static/not-the-token-at-all-0000/web/model.js")])
def test_requests_without_the_token_get_401(site, method, path):
    base, _, _ = site
    response = client(base, None).request(method, path)
    assert response.status_code == 401 and "farm model" in response.json()["error"]


def test_a_wrong_token_gets_401_in_header_query_or_static_path(site):
    base, token, _ = site
    wrong = "y" * len(token)
    assert client(base, wrong).get("/api/version").status_code == 401
    anonymous = client(base, None)
    assert anonymous.get("/api/version", params={"token": wrong}).status_code == 401
    assert anonymous.get(f"/static/{wrong}/web/model.js").status_code == 401
    assert anonymous.get("/api/version", params={"token": token}).status_code == 200
    page = anonymous.get("/", params={"token": token})
    assert page.status_code == 200 and f"/static/{token}/web/model.js" in page.text
    viewer = anonymous.get(f"/static/{token}/review/viewer.js")  # the review viewer, imported by the page
    assert viewer.status_code == 200 and viewer.headers["content-type"].startswith("text/javascript")


@pytest.mark.parametrize("path", ["/static/{t}/web/../server.py", "/static/{t}/web/%2e%2e/%2e%2e/cli.py",
                                  "/static/{t}/review/..%2f..%2fcli.py", "/static/{t}/web/%2fetc%2fpasswd"])
def test_paths_leading_outside_the_served_folders_are_refused(site, path):
    base, token, _ = site
    url = urlsplit(base)
    connection = http.client.HTTPConnection(url.hostname, url.port, timeout=10)
    connection.request("GET", path.format(t=token), headers={TOKEN_HEADER: token})  # sent as written
    assert connection.getresponse().status in (403, 404)
    connection.close()


def test_a_large_or_malformed_body_is_refused_and_the_session_stays(site):
    base, token, service = site
    api = client(base, token)
    version = api.get("/api/version").json()["version"]
    big = api.post("/api/stroke", content=b'{"points": [' + b"[0,0,0]," * (MAX_EDIT_BYTES // 8) + b"[0,0,0]]}")
    assert big.status_code == 413 and "allowed at most" in big.json()["error"]
    bad = api.post("/api/stroke", content=b"{not json")
    assert bad.status_code == 400 and "malformed JSON" in bad.json()["error"]
    listed = api.post("/api/grow", content=b"[1, 2]")
    assert listed.status_code == 400 and "allowed an object" in listed.json()["error"]
    assert api.get("/api/version").json()["version"] == version


def test_points_cross_the_api_in_y_up_and_live_in_the_session_z_up(site):
    base, token, service = site
    api = client(base, token)
    drawn = ring(5.0, 2.0)
    state = api.post("/api/stroke", json={"points": y_up(drawn)}).json()
    stored = service.history.present.strokes[-1]
    assert np.allclose(stored[:, 2], 5.0) and np.allclose(np.linalg.norm(stored[:, :2], axis=1), 2.0, atol=0.05)
    assert np.allclose(np.array(state["strokes"][-1])[:, 1], 5.0)  # back to the page: height is Y
    assert api.post("/api/undo").json()["version"] == state["version"] + 1


def test_a_refused_edit_is_a_json_error_and_changes_nothing(site):
    base, token, service = site
    api = client(base, token)
    before = api.post("/api/growth", json={"seed": 11}).json()  # a new edit: nothing left to redo
    for tool, body, message in [("stroke", {"points": [[0, 0, 0]]}, "stroke"), ("lobe", {}, "at least one"),
                                ("move", {"branch": 3}, "does not exist"), ("growth", {"preset": "oak"}, "unknown"),
                                ("growth", {"parameters": {"iterations": 1000}}, "iterations"),
                                ("redo", {}, "nothing to redo")]:
        response = api.post(f"/api/{tool}", json=body)
        assert response.status_code == 400 and message in response.json()["error"], (tool, response.text)
    assert api.get("/api/version").json() == before


def test_grow_serves_the_current_version_and_drops_an_overtaken_one(site, monkeypatch):
    base, token, service = site
    api = client(base, token)
    api.post("/api/stroke", json={"points": y_up(ring(4.0, 2.5))})
    api.post("/api/stroke", json={"points": y_up(ring(7.0, 2.0))})
    version = api.post("/api/lobe").json()["version"]
    stale = api.post("/api/grow", json={"version": version - 1})
    assert stale.status_code == 409 and "dropped" in stale.json()["error"]
    grown = api.post("/api/grow", json={"version": version})
    assert grown.status_code == 200 and grown.content[:4] == b"glTF"
    assert grown.headers["X-Session-Version"] == str(version)
    # An edit that lands while the tree grows: the grown tree is dropped, not sent.
    slow = service_module.session_glb

    def grow_while_editing(session):
        service.edit("growth", {"seed": 3})
        return slow(session)

    monkeypatch.setattr(service_module, "session_glb", grow_while_editing)
    service.edit("growth", {"seed": 2})  # a state not grown yet (grown states are kept)
    with pytest.raises(Overtaken, match="a newer edit"):
        service.grow(service.version)


def test_a_surface_drag_moves_the_handle_to_its_target_and_leaves_far_vertices(site):
    base, token, service = site
    api = client(base, token)
    api.post("/api/stroke", json={"points": y_up(ring(2.0, 2.0))})
    api.post("/api/stroke", json={"points": y_up(ring(5.0, 2.0))})
    api.post("/api/lobe")
    lobe = len(service.history.present.lobes) - 1
    before = np.array(service.history.present.lobes[lobe].vertices)
    handle = int(np.argmax(before[:, 0]))
    target = before[handle] + [0.8, 0.0, 0.0]
    state = api.post("/api/drag-surface", json={"lobe": lobe, "handle": handle, "target": y_up([target])[0],
                                                "radius": 1.5}).json()
    after = np.array(service.history.present.lobes[lobe].vertices)
    assert np.linalg.norm(after[handle] - target) < 1e-3
    # Far samples of the strokes stay (a cap's apex, made from its ring, follows the ring's moved samples).
    samples = np.vstack(service.history.present.lobes[lobe].strokes)
    on_strokes = np.array([np.abs(samples - v).sum(axis=1).min() < 1e-12 for v in after])
    far = (np.linalg.norm(before - before[handle], axis=1) > 1.5) & on_strokes
    assert far.sum() > len(after) // 4 and np.allclose(after[far], before[far], atol=1e-9)
    assert np.allclose(np.array(state["lobes"][lobe]["vertices"])[handle], y_up([target])[0], atol=1e-3)
    bad = api.post("/api/drag-surface", json={"lobe": lobe, "handle": 10**6, "target": [0, 0, 0], "radius": 1})
    assert bad.status_code == 400 and "lobe vertex" in bad.json()["error"]


def test_save_and_load_return_the_session_and_refuse_what_is_not_one(site):
    base, token, service = site
    api = client(base, token)
    api.post("/api/branch", json={"points": y_up([[0, 0, 0], [0, 0, 3]])})
    saved = api.post("/api/save", json={"name": "first"}).json()
    text = api.get("/api/session").text
    assert json.loads(text)["format"] == "treefarm-model-session" and saved["bytes"] == len(text.encode())
    api.post("/api/branch", json={"points": y_up([[0, 0, 1], [1, 0, 2]])})
    loaded = api.post("/api/load", json={"name": "first"}).json()
    assert api.get("/api/session").text == text and loaded["can_undo"]
    version = loaded["version"]
    for body, status, message in [({"name": "../etc"}, 400, "session name"), ({"name": "missing"}, 400, "no saved"),
                                  ({"format": "something else"}, 400, "not a modelling session"),
                                  ({**json.loads(text), "format_version": 2}, 400, "newer treefarm")]:
        response = api.post("/api/load", json=body)
        assert response.status_code == status and message in response.json()["error"]
    assert api.get("/api/version").json()["version"] == version and api.get("/api/session").text == text


def test_saving_into_a_file_instead_of_a_folder_is_a_clear_error(tmp_path):
    (tmp_path / "taken").write_text("not a folder")
    with model_server(out=tmp_path / "taken") as (base, token, _):
        response = client(base, token).post("/api/save", json={"name": "x"})
    assert response.status_code == 400 and "cannot save the session" in response.json()["error"]


def test_send_to_library_without_a_library_is_a_clear_error(site):
    base, token, _ = site
    response = client(base, token).post("/api/send-to-library")
    assert response.status_code == 400 and "--library DIR" in response.json()["error"]


def test_send_to_a_folder_that_is_not_a_library_is_refused_and_writes_nothing(tmp_path):
    folder = tmp_path / "not_a_library"
    folder.mkdir()
    with model_server(library=folder) as (base, token, _):
        api = client(base, token)
        api.post("/api/stroke", json={"points": y_up(ring(4.0, 2.5))})
        api.post("/api/stroke", json={"points": y_up(ring(7.0, 2.0))})
        api.post("/api/lobe")
        response = api.post("/api/send-to-library")
    assert response.status_code == 400 and "farm library --out DIR" in response.json()["error"]
    assert list(folder.iterdir()) == []


def test_a_taken_port_is_a_one_line_error(capsys):
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    try:
        assert main(["model", "--port", str(taken.getsockname()[1])]) == 2
    finally:
        taken.close()
    error = capsys.readouterr().err.strip()
    assert error.startswith("farm: error: cannot listen on 127.0.0.1:") and "--port" in error and "\n" not in error


@pytest.mark.parametrize("flags, message", [(["--tls-cert", "c.pem"], "go together"),
                                            (["--tls-self-signed", "--tls-key", "k.pem"], "not both"),
                                            (["--token", "short"], "--token 'short' is invalid")])
def test_bad_flags_are_one_line_errors(flags, message, capsys):
    assert main(["model", "--port", "0", *flags]) == 2
    assert message in capsys.readouterr().err


def test_https_with_a_self_signed_certificate_serves_the_page(tmp_path):
    cert, key, fingerprint = self_signed_certificate(tmp_path, ["127.0.0.1"])
    assert fingerprint == certificate_fingerprint(cert.read_bytes()) and len(fingerprint.split(":")) == 32
    assert key.stat().st_mode & 0o077 == 0  # the key is its owner's only
    with model_server(tls=(str(cert), str(key))) as (base, token, _):
        assert base.startswith("https://")
        context = ssl.create_default_context(cafile=str(cert))
        response = httpx.get(f"{base}/api/version", params={"token": token}, verify=context, timeout=30)
        assert response.status_code == 200 and response.json()["version"] == 0
        with pytest.raises(httpx.ConnectError):
            httpx.get(f"{base}/api/version", params={"token": token}, timeout=30)  # untrusted without the cert


def test_farm_model_serves_https_with_the_printed_fingerprint_and_url(tmp_path):
    process = subprocess.Popen([sys.executable, "-m", "farm.cli", "model", "--port", "0", "--tls-self-signed",
                                "--out", str(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               cwd=Path(__file__).resolve().parents[2])
    try:
        fingerprint = re.search(r"SHA-256 ([0-9A-F:]+)", process.stdout.readline()).group(1)
        url = re.search(r"open (https://127\.0\.0\.1:\d+/\?token=[A-Za-z0-9_-]+)", process.stdout.readline()).group(1)
        cert = tmp_path / "tls" / "cert.pem"
        assert fingerprint == certificate_fingerprint(cert.read_bytes())
        context = ssl.create_default_context(cafile=str(cert))
        assert httpx.get(url, verify=context, timeout=30).status_code == 200
        assert httpx.get(url.split("?")[0], verify=context, timeout=30).status_code == 401
    finally:
        process.terminate()
        process.wait(timeout=20)
