"""The modelling server's HTTP layer: the page, its static files and one JSON endpoint per tool, behind the access
token of `farm.token_server` (header, `?token=` or the /static/TOKEN/ prefix), over HTTP or HTTPS.

POST /api/TOOL (stroke, lobe, drag-stroke, drag-surface, branch, move, brush, growth), /api/undo, /api/redo,
/api/grow ({"version": V} -> the GLB of version V, or 409 when a newer edit overtook it), /api/save, /api/load,
/api/send-to-library; GET /api/version (the session's state) and /api/session (its JSON file).
Errors: {"error": message} with 400 (refused edit), 403, 404, 409 (overtaken), 413 (body too large).
"""
from __future__ import annotations

from pathlib import Path

from species.errors import TreefarmError

from ..token_server import (NotServed, TokenGuard, check_token, error_handlers, error_response, page_head,
                            read_json_body, static_response, three_root)
from .service import TOOLS, ModelService, Overtaken

__all__ = ["create_model_app", "WEB_FOLDER", "MAX_EDIT_BYTES", "MAX_SESSION_BYTES"]

WEB_FOLDER = Path(__file__).resolve().parent / "web"
# A hand-drawn stroke is a few hundred points; a whole session file (lobe meshes, markers) is far larger.
MAX_EDIT_BYTES = 256 * 1024
MAX_SESSION_BYTES = 16 * 1024 * 1024


def create_model_app(service: ModelService, token: str):
    """The Starlette application of one ModelService, in the token guard."""
    from starlette.applications import Starlette
    from starlette.concurrency import run_in_threadpool
    from starlette.requests import Request
    from starlette.responses import HTMLResponse, JSONResponse, Response
    from starlette.routing import Route

    check_token(token)
    roots = {"web": WEB_FOLDER, "three": three_root(), "review": WEB_FOLDER.parents[1] / "review" / "web"}

    def page(request: Request):
        head = page_head(token, "treefarm model", "model.js")
        html = (WEB_FOLDER / "index.html").read_text().replace("{{HEAD}}", head)
        return HTMLResponse(html, headers={"Cache-Control": "no-store"})

    def static(request: Request):
        return static_response(roots, request.path_params["root"], request.path_params["path"], WEB_FOLDER)

    async def body_of(request: Request, limit: int = MAX_EDIT_BYTES):
        """(JSON object, None), or (None, an error response); an empty body is {}."""
        what = request.url.path.rsplit("/", 1)[-1]
        parsed, refused = await read_json_body(request, limit, what, empty={})
        if refused is None and not isinstance(parsed, dict):
            return None, error_response(400, f"{what} body is a JSON {type(parsed).__name__}; allowed an object")
        return parsed, refused

    def tool_route(tool: str):
        async def apply(request: Request):
            body, refused = await body_of(request)
            return refused or JSONResponse(await run_in_threadpool(service.edit, tool, body))
        return Route(f"/api/{tool}", apply, methods=["POST"])

    async def undo(request: Request):
        return JSONResponse(await run_in_threadpool(service.undo))

    async def redo(request: Request):
        return JSONResponse(await run_in_threadpool(service.redo))

    async def version(request: Request):
        return JSONResponse(await run_in_threadpool(service.state))

    async def grow(request: Request):
        body, refused = await body_of(request)
        if refused:
            return refused
        number = body.get("version")
        if isinstance(number, bool) or not isinstance(number, int):
            return error_response(400, f"grow needs the session's \"version\" (an integer); got {number!r}")
        grown, glb = await run_in_threadpool(service.grow, number)
        return Response(glb, media_type="model/gltf-binary", headers={"X-Session-Version": str(grown)})

    async def session_file(request: Request):
        text = await run_in_threadpool(service.session_json)
        return Response(text, media_type="application/json",
                        headers={"Content-Disposition": 'attachment; filename="session.json"'})

    async def save(request: Request):
        body, refused = await body_of(request)
        return refused or JSONResponse(await run_in_threadpool(service.save, body.get("name", "session")))

    async def load(request: Request):
        body, refused = await body_of(request, MAX_SESSION_BYTES)
        return refused or JSONResponse(await run_in_threadpool(service.load, body))

    async def send(request: Request):
        return JSONResponse(await run_in_threadpool(service.send_to_library))

    routes = [Route("/", page), Route("/static/{token}/{root}/{path:path}", static),
              *[tool_route(tool) for tool in TOOLS],
              Route("/api/undo", undo, methods=["POST"]), Route("/api/redo", redo, methods=["POST"]),
              Route("/api/version", version), Route("/api/grow", grow, methods=["POST"]),
              Route("/api/session", session_file), Route("/api/save", save, methods=["POST"]),
              Route("/api/load", load, methods=["POST"]), Route("/api/send-to-library", send, methods=["POST"])]
    statuses = {Overtaken: 409, TreefarmError: 400, NotServed: 404, PermissionError: 403}
    app = Starlette(routes=routes, exception_handlers=error_handlers(statuses))
    return TokenGuard(app, token, command="farm model")
