"""Review client benchmark: page load to the first tree drawn, GLB sizes and API latencies, 100-tree batch, localhost.

The batch is the default job's species mix cut to 100 trees, 64 px images, made once by the real pipeline under
out/bench_review/ (a re-run reuses it). The page runs in headless Debian chromium with WebGL on SwiftShader (CPU).
Run: python -m benchmarks.bench_review [--trees 100] [--loads 5] [--out out/bench_review]
"""
from __future__ import annotations

import statistics
import tempfile
from dataclasses import replace
from pathlib import Path

import httpx
import numpy as np
from playwright.sync_api import sync_playwright

from benchmarks.harness import Benchmark, arguments, time_case
from farm.dataset import to_pandas
from farm.jobs import RenderSpec, default_spec
from farm.pipeline import run_job
from farm.review.browser import launch_chromium
from farm.review.server import TOKEN_HEADER, ReviewServer, create_app, new_token
from farm.review.service import ReviewService

TARGET_FIRST_TREE_MS = 2000.0  # the first tree on screen within 2 s


def make_batch(out: Path, trees: int) -> None:
    spec = replace(default_spec().with_trees(trees), name="bench_review", shard_size=10,
                   render=RenderSpec(rig="tsn4", size=64, outputs=("depth", "sketch_tsn")))
    run_job(spec, str(out), progress=True)  # a re-run finds every shard finished and only reads the manifest


def timed_get(client, path: str, repeats: int = 5) -> float:
    """Median milliseconds of a GET (status checked)."""
    timing = time_case(lambda: client.get(path).raise_for_status(), repeats)
    return timing.ms()


def page_loads(url: str, loads: int) -> tuple[list[float], list[float]]:
    """(first tree drawn, DOMContentLoaded) in ms after navigation start, each load in a fresh browser context."""
    drawn, ready = [], []
    with sync_playwright() as playwright:
        browser = launch_chromium(playwright)
        for _ in range(loads):
            context = browser.new_context(viewport={"width": 1280, "height": 800})
            page = context.new_page()
            page.goto(url)
            page.wait_for_function("window.firstTreeDrawnAt !== undefined", timeout=60_000)
            drawn.append(page.evaluate("window.firstTreeDrawnAt"))
            ready.append(page.evaluate("performance.getEntriesByType('navigation')[0].domContentLoadedEventEnd"))
            context.close()
        browser.close()
    return drawn, ready


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--trees", type=int, default=100)
    parser.add_argument("--loads", type=int, default=5, help="page loads to time (fresh browser context each)")
    parser.add_argument("--out", default="out/bench_review")
    args = parser.parse_args()
    bench = Benchmark("review", "The review client: page load to the first tree drawn, API latencies", args)
    out = Path(args.out)
    make_batch(out, args.trees)
    trees = to_pandas(str(out), columns=["tree_id", "index", "species", "glb", "bark_triangles", "leaf_triangles"])
    glb_mb = trees["glb"].map(lambda b: len(b) if b is not None else 0).to_numpy() / 2**20
    first = trees.sort_values("index").iloc[0]

    with tempfile.TemporaryDirectory() as scratch:
        db = Path(scratch) / "reviews.sqlite"
        cold = time_case(lambda: ReviewService(str(out), db), 1)
        service, cold_start_s = cold.result, cold.median
        warm_start_s = time_case(lambda: ReviewService(str(out), db), 1).median
        token = new_token()
        with ReviewServer(create_app(service, token)) as server:
            with httpx.Client(base_url=server.base, headers={TOKEN_HEADER: token}) as client:
                list_ms = timed_get(client, "/api/trees?per_page=24")
                glb_ms = timed_get(client, f"/api/trees/{first.tree_id}/glb")
                depth_ms = timed_get(client, f"/api/trees/{first.tree_id}/views/0/depth.png")
            drawn, ready = page_loads(server.url(token), args.loads)

    rows = [
        ("trees in the batch", f"{len(trees)}", ""),
        ("server start: index + QA flags (s)", f"{cold_start_s:.2f}", "computed once per batch"),
        ("server start, QA flags cached (s)", f"{warm_start_s:.2f}", ""),
        ("GET tree page of 24 (ms, median)", f"{list_ms:.1f}", ""),
        (f"GET first tree GLB (ms, median, {len(first.glb) / 2**20:.2f} MiB)", f"{glb_ms:.1f}", ""),
        ("GET depth PNG as 8-bit (ms, median)", f"{depth_ms:.1f}", ""),
        ("GLB size per tree (MiB): median", f"{np.median(glb_mb):.2f}", ""),
        ("GLB size per tree (MiB): mean / max", f"{glb_mb.mean():.2f} / {glb_mb.max():.2f}", ""),
        ("page DOMContentLoaded (ms, median)", f"{statistics.median(ready):.0f}", ""),
        (f"page load -> first tree drawn (ms, median of {len(drawn)})", f"{statistics.median(drawn):.0f}",
         f"<= {TARGET_FIRST_TREE_MS:.0f}"),
        ("page load -> first tree drawn (ms, worst)", f"{max(drawn):.0f}", f"<= {TARGET_FIRST_TREE_MS:.0f}"),
    ]
    bench.table(f"review client, {len(trees)}-tree batch on localhost (first tree: {first.species}, "
                f"{int(first.bark_triangles + first.leaf_triangles):,} triangles); WebGL on SwiftShader (CPU)",
                ["measure", "value", "reference"], rows)
    bench.figure("page load to the first tree drawn", statistics.median(drawn), "ms",
                 f"median of {len(drawn)} loads; target <= {TARGET_FIRST_TREE_MS:.0f} ms")
    bench.write()


if __name__ == "__main__":
    main()
