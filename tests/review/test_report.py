"""`farm review REPORT_DIR`: an evaluation report's rows worst first, their panels, the token, and the page.

The report folder is written by hand (evaluation.json, a few metrics.parquet rows, small PNG panels), not by
running an evaluation, so these tests take well under a second each (the browser one excepted).
"""
from __future__ import annotations

import io
import json
import math
from pathlib import Path

import httpx
import numpy as np
import pandas as pd
import pytest
from PIL import Image

import farm.review.report as report_module
from farm.cli import main
from farm.evaluate.job import FORMAT, JOB_FILE, METRICS_FILE
from farm.review.report import EvaluationReport, is_report
from farm.review.server import TOKEN_HEADER, ReviewServer, create_app, new_token
from farm.review.store import ReviewError


NAN = math.nan
# (method, source, tree_id, status, crown_iou_unseen, cloud_fit_10cm, silhouette_iou_input, node_hausdorff)
ROWS = [
    ("params", "held-out", "t-0", "ok", 0.8, NAN, 0.7, 0.10),
    ("params", "held-out", "t-1", "ok", 0.3, NAN, 0.5, 0.40),
    ("params", "held-out", "t-2", "ok", 0.6, NAN, 0.6, 0.20),
    ("params", "held-out", "t-3", "failed", NAN, NAN, NAN, NAN),
    ("params", "input", "photo-a", "ok", NAN, NAN, 0.4, NAN),
    ("cloud", "held-out", "t-0", "ok", NAN, 0.9, NAN, 0.30),
    ("cloud", "held-out", "t-1", "ok", NAN, 0.5, NAN, 0.05),
]
# Worst first: the failed row; then each rank metric's rows by their worst-first share (crown IoU for params'
# trees, cloud fit for cloud's, input-view silhouette IoU for params' real input), ties in method order.
WORST_FIRST = [("params", "t-3"), ("cloud", "t-1"), ("params", "t-1"), ("params", "photo-a"), ("params", "t-2"),
               ("cloud", "t-0"), ("params", "t-0")]


def _png(colour: tuple[int, int, int]) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(np.full((24, 72, 3), colour, np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


def write_fake_report(folder: Path) -> Path:
    """A report folder as `farm evaluate` leaves it, with the rows above and one PNG panel per ok row."""
    folder.mkdir(parents=True)
    (folder / JOB_FILE).write_text(json.dumps({"format": FORMAT, "methods": ["params", "cloud"], "part": "all",
                                               "trees": 4, "inputs": None, "models": None, "settings": {},
                                               "datasets": [{"name": "fake", "path": "/nowhere"}]}))
    records = []
    for i, (method, source, tree_id, status, crown, cloud, silhouette, hausdorff) in enumerate(ROWS):
        panel = None
        if status == "ok":
            panel = f"panels/{method}/{source}-{tree_id}.png"
            (folder / panel).parent.mkdir(parents=True, exist_ok=True)
            (folder / panel).write_bytes(_png((30 * i, 255 - 30 * i, 90)))
        records.append({"method": method, "source": source, "dataset": "/nowhere", "spec_digest": "abc",
                        "tree_id": tree_id, "species": "maple", "status": status,
                        "error": "grow failed: no trunk" if status != "ok" else None,
                        "crown_iou_unseen": crown, "cloud_fit_10cm": cloud, "silhouette_iou_input": silhouette,
                        "node_hausdorff": hausdorff, "seconds_unit": 1.5, "models": "{}", "panel": panel})
    pd.DataFrame(records).to_parquet(folder / METRICS_FILE)
    return folder


@pytest.fixture
def fake_report(tmp_path) -> Path:
    return write_fake_report(tmp_path / "report")


@pytest.fixture
def report_server(fake_report):
    """(base URL, token, report folder) of a server over the fake report."""
    token = new_token()
    server = ReviewServer(create_app(EvaluationReport(fake_report), token), "127.0.0.1", 0).start()
    try:
        yield server.base, token, fake_report
    finally:
        server.stop()


def client(base: str, token: str | None) -> httpx.Client:
    return httpx.Client(base_url=base, headers={TOKEN_HEADER: token} if token else {}, timeout=30)


def test_rows_come_failed_first_then_worst_first_by_each_methods_rank_metric(report_server):
    base, token, _ = report_server
    with client(base, token) as api:
        response = api.get("/api/report/rows")
    assert response.status_code == 200 and "NaN" not in response.text
    rows = response.json()["rows"]
    assert [(r["method"], r["tree_id"]) for r in rows] == WORST_FIRST
    assert [r["index"] for r in rows] == list(range(len(ROWS)))
    assert rows[0]["status"] == "failed" and rows[0]["rank_value"] is None and rows[0]["panel"] is None
    by_method = {(r["method"], r["source"]): r["rank_metric"] for r in rows}
    assert by_method == {("params", "held-out"): "crown_iou_unseen", ("cloud", "held-out"): "cloud_fit_10cm",
                         ("params", "input"): "silhouette_iou_input"}
    crown = [r["rank_value"] for r in rows if r["rank_metric"] == "crown_iou_unseen" and r["status"] == "ok"]
    assert crown == [0.3, 0.6, 0.8]  # higher is better: the lowest IoU is the worst
    assert "cloud_fit_10cm" not in rows[2]["metrics"]  # a metric that does not apply is left out, not NaN


def test_the_method_filter_keeps_one_methods_rows_in_the_same_order(report_server):
    base, token, _ = report_server
    with client(base, token) as api:
        cloud = api.get("/api/report/rows", params={"method": "cloud"}).json()["rows"]
        unknown = api.get("/api/report/rows", params={"method": "nope"})
        bad_field = api.get("/api/report/rows", params={"species": "maple"})
    assert [(r["tree_id"], r["rank_value"]) for r in cloud] == [("t-1", 0.5), ("t-0", 0.9)]
    assert unknown.status_code == 400 and "allowed cloud, params" in unknown.json()["error"]
    assert bad_field.status_code == 400 and "allowed method" in bad_field.json()["error"]


def test_a_lower_is_better_rank_metric_puts_the_largest_value_first(fake_report, monkeypatch):
    monkeypatch.setattr(report_module, "GALLERY_METRIC", ("node_hausdorff",))
    rows = EvaluationReport(fake_report).rows("params")
    assert [r["tree_id"] for r in rows] == ["t-3", "t-1", "t-2", "t-0", "photo-a"]  # no node metric: last
    assert [r["rank_value"] for r in rows[1:4]] == [0.40, 0.20, 0.10]


def test_the_summary_names_the_job_counts_and_metric_columns_with_directions(report_server):
    base, token, _ = report_server
    with client(base, token) as api:
        summary = api.get("/api/report").json()
    assert summary["job"]["format"] == FORMAT and summary["rows"] == len(ROWS)
    assert summary["counts"] == {"ok": 6, "failed": 1, "error": 0} and summary["methods"] == ["cloud", "params"]
    columns = {c["name"]: c for c in summary["columns"]}
    assert set(columns) == {"crown_iou_unseen", "cloud_fit_10cm", "silhouette_iou_input", "node_hausdorff"}
    assert columns["crown_iou_unseen"]["higher_is_better"] is True
    assert columns["node_hausdorff"]["higher_is_better"] is False and columns["node_hausdorff"]["label"]


def test_the_panel_route_returns_the_rows_png(report_server):
    base, token, folder = report_server
    with client(base, token) as api:
        rows = api.get("/api/report/rows").json()["rows"]
        panel = api.get(f"/api/report/rows/{rows[1]['index']}/panel")
        failed = api.get(f"/api/report/rows/{rows[0]['index']}/panel")
        beyond = api.get(f"/api/report/rows/{len(rows)}/panel")
    assert panel.status_code == 200 and panel.headers["content-type"] == "image/png"
    assert panel.content == (folder / rows[1]["panel"]).read_bytes()
    assert failed.status_code == 404 and "has no panel" in failed.json()["error"]
    assert beyond.status_code == 404 and f"no row {len(rows)}" in beyond.json()["error"]


@pytest.mark.parametrize("path", ["/", "/api/report", "/api/report/rows", "/api/report/rows/1/panel"])
def test_a_wrong_or_missing_token_is_refused(report_server, path):
    base, token, _ = report_server
    with client(base, "x" * len(token)) as wrong, client(base, None) as anonymous:
        assert wrong.get(path).status_code == 401
        assert anonymous.get(path).status_code == 401
        assert anonymous.get(path, params={"token": token}).status_code == 200


def test_the_page_loads_the_report_client_not_the_tree_review(report_server):
    base, token, _ = report_server
    with client(base, None) as anonymous:
        html = anonymous.get("/", params={"token": token}).text
        script = anonymous.get(f"/static/{token}/web/report.js")
    assert f"/static/{token}/web/report.js" in html and "web/review.js" not in html
    assert '<body class="report">' in html and script.status_code == 200
    with client(base, token) as api:
        assert api.get("/api/batches").status_code == 404  # no dataset routes over a report


def test_a_report_folder_without_metrics_parquet_is_a_one_line_error(fake_report, capsys):
    (fake_report / METRICS_FILE).unlink()
    with pytest.raises(ReviewError, match=f"{fake_report} holds no {METRICS_FILE}"):
        EvaluationReport(fake_report)
    assert main(["review", str(fake_report), "--port", "0"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith(f"farm: error: {fake_report} holds no {METRICS_FILE}") and "\n" not in error


def test_a_folder_without_evaluation_json_is_not_a_report(tmp_path):
    assert not is_report(tmp_path)
    with pytest.raises(ReviewError, match="not an evaluation report"):
        EvaluationReport(tmp_path)


def test_farm_review_of_a_report_prints_its_rows_and_writes_nothing_there(fake_report, capsys, monkeypatch):
    monkeypatch.setattr(ReviewServer, "run", lambda self: self.socket.close())  # return instead of serving
    before = sorted(p.relative_to(fake_report) for p in fake_report.rglob("*"))
    assert main(["review", str(fake_report), "--port", "0"]) == 0
    out = capsys.readouterr().out
    assert f"reviewing evaluation report {fake_report}: {len(ROWS)} rows (1 failed)" in out and "?token=" in out
    assert sorted(p.relative_to(fake_report) for p in fake_report.rglob("*")) == before  # no reviews.sqlite
    assert main(["review", str(fake_report), "--db", str(fake_report / "x.sqlite")]) == 2


# ------------------------------------------------------------------------------------------------ the page
def test_the_report_page_lists_the_rows_and_shows_a_rows_panel_on_click(chromium_browser, report_server):
    base, token, folder = report_server
    page = chromium_browser.new_page(viewport={"width": 1200, "height": 700})
    problems = []
    page.on("pageerror", lambda error: problems.append(f"page error: {error}"))
    page.on("console", lambda message: problems.append(f"console: {message.text}") if message.type == "error" else None)
    page.goto(f"{base}/?token={token}")
    page.wait_for_function(f"document.querySelectorAll('#report-table tbody tr').length === {len(ROWS)}")
    cells = page.locator("#report-table tbody tr").evaluate_all(
        "(rows) => rows.map((r) => [r.cells[1].textContent, r.cells[3].textContent, r.cells[4].textContent])")
    assert cells[0] == ["params", "t-3", "failed"]
    assert [(m.removesuffix(" (input)"), t) for m, t, _ in cells] == WORST_FIRST
    assert page.locator("#dataset").is_hidden() and page.locator("#report-table").is_visible()
    page.locator("#report-table tbody tr").nth(2).click()  # params t-1, crown IoU 0.3
    page.wait_for_function("window.lastPanelShown === 2")
    shown = page.evaluate("""async () => {
        const img = document.getElementById('report-panel');
        const bytes = new Uint8Array(await (await fetch(img.src)).arrayBuffer());
        return { width: img.naturalWidth, height: img.naturalHeight, rendered: img.getBoundingClientRect().width,
                 bytes: Array.from(bytes) };
    }""")
    rows = page.evaluate("window.reportApp.rows")
    assert bytes(shown["bytes"]) == (folder / rows[2]["panel"]).read_bytes()
    assert (shown["width"], shown["height"]) == (72, 24) and shown["rendered"] > 300  # drawn large
    assert "0.300" in page.locator("#report-row-metrics").inner_text()
    assert page.locator("#report-table tbody tr").nth(2).get_attribute("class") == "ok selected"
    page.close()
    assert problems == []
