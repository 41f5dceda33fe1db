"""The review server's HTTP layer: a Starlette app behind an access token, run by uvicorn on a bound socket.

Every request needs the token: header `X-Review-Token`, query `?token=`, or the `/static/TOKEN/...` path prefix
(so ES module imports, which cannot set headers, resolve relative to it). JSON errors: {"error": message}.
Over a dataset (a ReviewService) it serves the tree review; over an EvaluationReport, the report's rows and panels.
"""
from __future__ import annotations

from pathlib import Path

from ..token_server import (TOKEN_HEADER, NotServed, TokenGuard, TokenServer, check_token, error_handlers,
                            listen_socket, new_token, page_head, read_json_body, static_response, three_root)
from .index import NotFound
from .report import EvaluationReport
from .service import ReviewService, TreeQuery
from .store import ReviewError

__all__ = ["create_app", "ReviewServer", "new_token", "check_token", "static_roots", "listen_socket", "TOKEN_HEADER",
           "WEB_FOLDER"]

WEB_FOLDER = Path(__file__).resolve().parent / "web"
# Long enough for a verdict with its note; anything larger is refused before parsing.
MAX_BODY_BYTES = 64 * 1024
ReviewServer = TokenServer  # the name scripts and benchmarks know


def static_roots() -> dict[str, Path]:
    """Folders served under /static/TOKEN/NAME/: the web client and three.js from the project's node_modules."""
    return {"web": WEB_FOLDER, "three": three_root()}


def create_app(service: ReviewService | EvaluationReport, token: str, roots: dict[str, Path] | None = None):
    """The Starlette application for one ReviewService (a dataset) or EvaluationReport, in the token guard."""
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import HTMLResponse
    from starlette.routing import Route

    check_token(token)
    roots = static_roots() if roots is None else roots
    mode, script = ("report", "report.js") if isinstance(service, EvaluationReport) else ("dataset", "review.js")

    def page(request: Request):
        html = (WEB_FOLDER / "index.html").read_text().replace("{{HEAD}}", page_head(token, "treefarm review", script))
        return HTMLResponse(html.replace("{{MODE}}", mode), headers={"Cache-Control": "no-store"})

    def static(request: Request):
        return static_response(roots, request.path_params["root"], request.path_params["path"], WEB_FOLDER)

    routes = [Route("/", page), Route("/static/{token}/{root}/{path:path}", static)]
    routes += _report_routes(service) if mode == "report" else _dataset_routes(service)
    app = Starlette(routes=routes, exception_handlers=error_handlers({ReviewError: 400, NotFound: 404, NotServed: 404,
                                                                     PermissionError: 403}))
    return TokenGuard(app, token)


def _params(request) -> dict[str, str]:
    return {key: value for key, value in request.query_params.items()}


def _report_routes(report: EvaluationReport) -> list:
    """/api/report (job, counts, columns), /api/report/rows[?method=] (worst first), /api/report/rows/I/panel."""
    from starlette.responses import JSONResponse, Response
    from starlette.routing import Route

    def summary(request):
        return JSONResponse(report.summary())

    def rows(request):
        return JSONResponse({"rows": report.rows_query(_params(request))})

    def panel(request):
        return Response(report.panel_png(request.path_params["index"]), media_type="image/png",
                        headers={"Cache-Control": "max-age=3600"})

    return [Route("/api/report", summary), Route("/api/report/rows", rows),
            Route("/api/report/rows/{index:int}/panel", panel)]


def _dataset_routes(service: ReviewService) -> list:
    """The tree review: batches, filtered tree pages, one tree's GLB, skeleton and view images, verdicts."""
    from starlette.concurrency import run_in_threadpool
    from starlette.requests import Request
    from starlette.responses import JSONResponse, Response
    from starlette.routing import Route

    def batches(request: Request):
        return JSONResponse(service.summary())

    def trees(request: Request):
        return JSONResponse(service.list_trees(TreeQuery(_params(request))))

    def tree(request: Request):
        return JSONResponse(service.tree(request.path_params["tree_id"], request.query_params.get("reviewer")))

    def neighbours(request: Request):
        return JSONResponse(service.neighbours(request.path_params["tree_id"]))

    def glb(request: Request):
        return Response(service.index.glb(request.path_params["tree_id"]), media_type="model/gltf-binary")

    def skeleton(request: Request):
        return JSONResponse(service.index.skeleton(request.path_params["tree_id"]))

    def image(request: Request):
        name = request.path_params["output"]
        if not name.endswith(".png"):
            raise NotFound(f"image {name!r}: images are named OUTPUT.png")
        data = service.index.view_image(request.path_params["tree_id"], request.path_params["view"], name[:-4])
        return Response(data, media_type="image/png", headers={"Cache-Control": "max-age=3600"})

    async def verdicts(request: Request):
        if request.method == "GET":
            tree_id = request.query_params.get("tree_id")
            return JSONResponse({"verdicts": await run_in_threadpool(service.store.verdicts, tree_id)})
        parsed, refused = await read_json_body(request, MAX_BODY_BYTES, "verdict")
        if refused is not None:
            return refused
        return JSONResponse(await run_in_threadpool(service.post_verdict, parsed))

    return [
        Route("/api/batches", batches), Route("/api/trees", trees), Route("/api/trees/{tree_id}", tree),
        Route("/api/trees/{tree_id}/neighbours", neighbours), Route("/api/trees/{tree_id}/glb", glb),
        Route("/api/trees/{tree_id}/skeleton", skeleton),
        Route("/api/trees/{tree_id}/views/{view:int}/{output}", image),
        Route("/api/verdicts", verdicts, methods=["GET", "POST"]),
    ]
