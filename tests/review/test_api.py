"""The review server's HTTP API: token, path safety, errors, filters and paging, data from the shards, verdicts."""
from __future__ import annotations

import http.client
from concurrent.futures import ThreadPoolExecutor
from urllib.parse import urlsplit

import httpx
import numpy as np
import pyarrow.parquet as pq
import pytest

import farm.dataset as dataset
from farm.dataset.image_codec import decode_map, encode_map
from farm.review.index import viewable_png
from farm.review.server import TOKEN_HEADER

from conftest import running_server


def client(base: str, token: str | None) -> httpx.Client:
    headers = {TOKEN_HEADER: token} if token is not None else {}
    return httpx.Client(base_url=base, headers=headers, timeout=30)


def raw_get(base: str, path: str, token: str) -> int:
    """GET a path exactly as written (no client-side '..' normalisation); returns the status."""
    url = urlsplit(base)
    connection = http.client.HTTPConnection(url.hostname, url.port, timeout=10)
    connection.request("GET", path, headers={TOKEN_HEADER: token})
    status = connection.getresponse().status
    connection.close()
    return status


@pytest.mark.parametrize("path", ["/", "/api/batches", "/api/trees", "/api/trees/review-00000000/glb",
                                  "/static/not-the-token-at-all-0000/web/review.js"])
def test_requests_without_the_token_get_401(server, path):
    base, token, _ = server
    with client(base, None) as anonymous:
        response = anonymous.get(path)
    assert response.status_code == 401 and "token" in response.json()["error"]


def test_a_wrong_token_gets_401_in_header_query_or_static_path(server):
    base, token, _ = server
    wrong = "x" * len(token)
    with client(base, wrong) as bad:
        assert bad.get("/api/batches").status_code == 401
    with client(base, None) as anonymous:
        assert anonymous.get("/api/batches", params={"token": wrong}).status_code == 401
        assert anonymous.get(f"/static/{wrong}/web/review.js").status_code == 401
        assert anonymous.get("/api/batches", params={"token": token}).status_code == 200


def test_the_page_and_its_static_files_are_served_with_the_token(server):
    base, token, _ = server
    with client(base, None) as anonymous:
        page = anonymous.get("/", params={"token": token})
        assert page.status_code == 200 and f'/static/{token}/three/build/three.module.js' in page.text
        script = anonymous.get(f"/static/{token}/three/build/three.module.js")
        assert script.status_code == 200 and script.headers["content-type"].startswith("text/javascript")


@pytest.mark.parametrize("path", ["/static/{t}/web/../../store.py", "/static/{t}/web/%2e%2e/%2e%2e/store.py",
                                  "/static/{t}/three/..%2f..%2fpackage.json", "/static/{t}/web/%2fetc%2fpasswd"])
def test_paths_leading_outside_the_served_folders_are_refused(server, path):
    base, token, _ = server
    assert raw_get(base, path.format(t=token), token) in (403, 404)
    assert raw_get(base, path.format(t=token), token) != 200


def test_dot_dot_paths_are_refused_with_403_and_a_message(server):
    base, token, _ = server
    with client(base, token) as api:
        response = api.get(f"/static/{token}/web/%2e%2e/store.py")
    assert response.status_code == 403 and "outside" in response.json()["error"]


def test_malformed_json_gets_400_with_a_message(server):
    base, token, _ = server
    with client(base, token) as api:
        response = api.post("/api/verdicts", content=b'{"tree_id": "review-00000000", "verdict": ')
    assert response.status_code == 400 and "malformed JSON" in response.json()["error"]


@pytest.mark.parametrize("body, field", [({"tree_id": "review-00000000", "reviewer": "a", "verdict": "maybe"}, "verdict"),
                                         ({"tree_id": "review-00000000", "verdict": "approve"}, "reviewer"),
                                         ({"tree_id": "review-00000000", "reviewer": "a", "verdict": "flag"}, "note"),
                                         ([1, 2], "JSON object")])
def test_an_invalid_verdict_gets_400_naming_the_field(server, body, field):
    base, token, _ = server
    with client(base, token) as api:
        response = api.post("/api/verdicts", json=body)
    assert response.status_code == 400 and field in response.json()["error"]


def test_a_verdict_on_an_unknown_tree_gets_404(server):
    base, token, _ = server
    with client(base, token) as api:
        response = api.post("/api/verdicts", json={"tree_id": "nope", "reviewer": "a", "verdict": "approve"})
    assert response.status_code == 404 and "nope" in response.json()["error"]


def test_paging_lists_every_tree_once_in_index_order(server):
    base, token, _ = server
    with client(base, token) as api:
        pages = [api.get("/api/trees", params={"per_page": 4, "page": p}).json() for p in (1, 2)]
    ids = [t["tree_id"] for page in pages for t in page["trees"]]
    assert pages[0]["total"] == 6 and pages[0]["pages"] == 2
    assert ids == [f"review-{i:08d}" for i in range(6)]


def test_filters_by_species_generator_and_batch(server):
    base, token, _ = server
    with client(base, token) as api:
        palms = api.get("/api/trees", params={"species": "palm"}).json()["trees"]
        lsystems = api.get("/api/trees", params={"generator": "lsystem"}).json()["trees"]
        second = api.get("/api/trees", params={"batch": "part-00001"}).json()["trees"]
        unknown = api.get("/api/trees", params={"flag": "purple"})
    assert len(palms) == 2 and {t["species"] for t in palms} == {"palm"}
    assert len(lsystems) == 2 and {t["generator"] for t in lsystems} == {"lsystem"}
    assert [t["index"] for t in second] == [4, 5]
    assert unknown.status_code == 400 and "purple" in unknown.json()["error"]


def test_verdict_filter_follows_stored_verdicts(server):
    base, token, _ = server
    with client(base, token) as api:
        api.post("/api/verdicts", json={"tree_id": "review-00000002", "reviewer": "ann", "verdict": "reject"})
        rejected = api.get("/api/trees", params={"verdict": "reject"}).json()["trees"]
        unreviewed = api.get("/api/trees", params={"verdict": "none"}).json()["total"]
        mine = api.get("/api/trees", params={"verdict": "none", "reviewer": "bob"}).json()["total"]
    assert [t["tree_id"] for t in rejected] == ["review-00000002"] and rejected[0]["verdicts"] == {"reject": 1}
    assert unreviewed == 5 and mine == 6


def test_glb_comes_byte_for_byte_from_the_trees_shard(server, review_dataset):
    base, token, _ = server
    stored = pq.read_table(review_dataset / "trees/part-00001.parquet", columns=["tree_id", "glb"]).to_pylist()
    with client(base, token) as api:
        served = api.get(f"/api/trees/{stored[1]['tree_id']}/glb")
    assert served.headers["content-type"] == "model/gltf-binary"
    assert served.content == stored[1]["glb"] and served.content[:4] == b"glTF"


def test_depth_is_served_as_an_8_bit_png_bright_near_and_black_background(server, review_dataset):
    base, token, _ = server
    columns = ["tree_id", "view", "depth", "depth_scale", "depth_offset"]
    row = dataset.open(str(review_dataset), "views").to_table(columns=columns).slice(5, 1).to_pylist()[0]
    with client(base, token) as api:
        png = api.get(f"/api/trees/{row['tree_id']}/views/{row['view']}/depth.png").content
    shown = decode_map(png)
    metres = decode_map(row["depth"], row["depth_scale"], row["depth_offset"])
    assert shown.dtype == np.uint8 and shown.shape == metres.shape == (64, 64)
    assert np.array_equal(shown == 0, metres == 0)
    foreground = metres > 0
    nearest, farthest = np.argmin(np.where(foreground, metres, np.inf)), np.argmax(metres)
    assert shown.flat[nearest] > shown.flat[farthest]


def test_a_silhouette_map_is_served_black_outside_the_tree_not_red():
    silhouette = np.zeros((8, 8, 3), np.float32)
    silhouette[..., 0] = 1.0  # background: far depth, no gap, no mask
    silhouette[2:6, 2:6] = (0.4, 0.1, 1.0)  # the tree
    png, scale, offset = encode_map("silhouette", silhouette)
    shown = decode_map(viewable_png("silhouette", png, scale, offset))
    outside = np.ones((8, 8), bool)
    outside[2:6, 2:6] = False
    assert (shown[outside] == 0).all() and (shown[~outside][:, 2] == 255).all()


def test_sketch_png_is_served_as_stored_and_unknown_outputs_are_404(server, review_dataset):
    base, token, _ = server
    row = dataset.open(str(review_dataset), "views").to_table(columns=["tree_id", "view", "sketch_tsn"]).to_pylist()[3]
    with client(base, token) as api:
        assert api.get(f"/api/trees/{row['tree_id']}/views/{row['view']}/sketch_tsn.png").content == row["sketch_tsn"]
        assert api.get(f"/api/trees/{row['tree_id']}/views/{row['view']}/normals.png").status_code == 404
        assert api.get(f"/api/trees/{row['tree_id']}/views/99/sketch_tsn.png").status_code == 404


def test_tree_details_carry_parameters_views_and_the_skeleton(server, review_dataset):
    base, token, _ = server
    row = pq.read_table(review_dataset / "trees/part-00000.parquet", columns=["tree_id", "n_nodes", "params_json"]).to_pylist()[2]
    with client(base, token) as api:
        detail = api.get(f"/api/trees/{row['tree_id']}").json()
        skeleton = api.get(f"/api/trees/{row['tree_id']}/skeleton").json()
    assert detail["params"]["generator"] == detail["generator"] and [v["name"] for v in detail["views"]][:1] == ["front"]
    assert len(skeleton["positions"]) == 3 * row["n_nodes"] and len(skeleton["parent"]) == row["n_nodes"]


def test_concurrent_verdicts_are_each_stored_exactly_once_and_survive_a_restart(review_dataset, tmp_path):
    db = tmp_path / "reviews.sqlite"
    trees = [f"review-{i:08d}" for i in range(6)]
    verdicts = [{"tree_id": trees[k % 6], "reviewer": f"reviewer-{k // 6:02d}", "verdict": ("approve", "reject")[k % 2],
                 "note": f"verdict {k}"} for k in range(200)]
    with running_server(review_dataset, db) as (base, token, service):
        def post_all(chunk):
            with client(base, token) as api:  # one client per thread: several reviewers at once
                return [api.post("/api/verdicts", json=body).status_code for body in chunk]

        # Every verdict is sent twice, by different clients: the store keeps one per (reviewer, tree).
        chunks = [verdicts[i::8] for i in range(8)] + [verdicts[i::5] for i in range(5)]
        with ThreadPoolExecutor(max_workers=len(chunks)) as pool:
            statuses = [s for chunk in pool.map(post_all, chunks) for s in chunk]
        assert statuses == [200] * 400
    with running_server(review_dataset, db) as (base, token, _):
        with client(base, token) as api:
            stored = api.get("/api/verdicts").json()["verdicts"]
    assert len(stored) == 200
    key = lambda v: (v["tree_id"], v["reviewer"])  # noqa: E731
    assert sorted((key(v), v["verdict"], v["note"]) for v in stored) == \
        sorted((key(v), v["verdict"], v["note"]) for v in verdicts)
