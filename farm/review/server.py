"""The review server's HTTP layer: a Starlette app behind an access token, run by uvicorn on a bound socket.

Every request needs the token: header `X-Review-Token`, query `?token=`, or the `/static/TOKEN/...` path prefix
(so ES module imports, which cannot set headers, resolve relative to it). JSON errors: {"error": message}.
Over a dataset (a ReviewService) it serves the tree review; over an EvaluationReport, the report's rows and panels.
"""
from __future__ import annotations

import errno
import hmac
import json
import mimetypes
import re
import secrets
import socket
import threading
import time
from pathlib import Path
from urllib.parse import parse_qs

from .index import NotFound
from .report import EvaluationReport
from .service import ReviewService, TreeQuery
from .store import ReviewError

__all__ = ["create_app", "ReviewServer", "new_token", "check_token", "static_roots", "TOKEN_HEADER", "WEB_FOLDER"]

TOKEN_HEADER = "x-review-token"
WEB_FOLDER = Path(__file__).resolve().parent / "web"
_TOKEN_PATTERN = re.compile(r"^[A-Za-z0-9_-]{16,128}$")
# Long enough for a verdict with its note; anything larger is refused before parsing.
MAX_BODY_BYTES = 64 * 1024


def new_token() -> str:
    return secrets.token_urlsafe(24)


def check_token(token: str) -> str:
    if not isinstance(token, str) or not _TOKEN_PATTERN.match(token):
        raise ReviewError(f"--token {token!r} is invalid: allowed 16-128 letters, digits, '-' or '_'")
    return token


def static_roots() -> dict[str, Path]:
    """Folders served under /static/TOKEN/NAME/: the web client and three.js from the project's node_modules."""
    three = Path(__file__).resolve().parents[2] / "node_modules" / "three"
    if not (three / "build" / "three.module.js").is_file():
        raise ReviewError(f"three.js is not installed at {three}: run `make node-env` (npm ci) in the project root")
    return {"web": WEB_FOLDER, "three": three}


class TokenGuard:
    """ASGI middleware: a request without the right token gets 401 before it reaches any route."""

    def __init__(self, app, token: str):
        self.app, self.token = app, token.encode()

    def _presented(self, scope) -> bytes:
        for name, value in scope.get("headers", []):
            if name == TOKEN_HEADER.encode():
                return value
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        if "token" in query:
            return query["token"][0].encode("latin-1")
        parts = scope.get("path", "").split("/")
        if len(parts) > 3 and parts[1] == "static":
            return parts[2].encode("latin-1")
        return b""

    async def __call__(self, scope, receive, send):
        if scope["type"] == "websocket" and not hmac.compare_digest(self._presented(scope), self.token):
            await send({"type": "websocket.close", "code": 1008})  # policy violation: no token
            return
        if scope["type"] == "http" and not hmac.compare_digest(self._presented(scope), self.token):
            from starlette.responses import JSONResponse

            response = JSONResponse({"error": "missing or wrong access token: open the URL that `farm review` "
                                              "printed (it carries ?token=)"}, status_code=401)
            await response(scope, receive, send)
            return
        await self.app(scope, receive, send)


def _error(status: int, message: str):
    from starlette.responses import JSONResponse

    return JSONResponse({"error": message}, status_code=status)


def _safe_file(root: Path, relative: str) -> Path:
    """`relative` under `root`, refusing '..', absolute paths and links that lead outside it."""
    parts = relative.replace("\\", "/").split("/")
    if relative.startswith("/") or ".." in parts or "\0" in relative:
        raise PermissionError(f"path {relative!r} leads outside the served folder")
    target = (root / relative).resolve()
    if not target.is_relative_to(root.resolve()):
        raise PermissionError(f"path {relative!r} leads outside the served folder")
    if not target.is_file():
        raise NotFound(f"no file {relative!r}")
    return target


def create_app(service: ReviewService | EvaluationReport, token: str, roots: dict[str, Path] | None = None):
    """The Starlette application for one ReviewService (a dataset) or EvaluationReport, in the token guard."""
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import HTMLResponse, Response
    from starlette.routing import Route

    check_token(token)
    roots = static_roots() if roots is None else roots
    mode, script = ("report", "report.js") if isinstance(service, EvaluationReport) else ("dataset", "review.js")

    def page(request: Request):
        html = (WEB_FOLDER / "index.html").read_text().replace("{{MODE}}", mode).replace("{{SCRIPT}}", script)
        return HTMLResponse(html.replace("{{TOKEN}}", token), headers={"Cache-Control": "no-store"})

    def static(request: Request):
        root = roots.get(request.path_params["root"])
        if root is None:
            raise NotFound(f"no static folder {request.path_params['root']!r}; folders: {', '.join(roots)}")
        target = _safe_file(root, request.path_params["path"])
        media = "text/javascript" if target.suffix in (".js", ".mjs") else mimetypes.guess_type(target.name)[0]
        return Response(target.read_bytes(), media_type=media or "application/octet-stream",
                        headers={"Cache-Control": "max-age=3600" if root != WEB_FOLDER else "no-cache"})

    async def review_error(request, exc):
        return _error(400, str(exc))

    async def not_found(request, exc):
        return _error(404, str(exc))

    async def forbidden(request, exc):
        return _error(403, str(exc))

    routes = [Route("/", page), Route("/static/{token}/{root}/{path:path}", static)]
    routes += _report_routes(service) if mode == "report" else _dataset_routes(service)
    app = Starlette(routes=routes, exception_handlers={ReviewError: review_error, NotFound: not_found,
                                                       PermissionError: forbidden})
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
        body = await request.body()
        if len(body) > MAX_BODY_BYTES:
            return _error(413, f"verdict body of {len(body)} bytes; allowed at most {MAX_BODY_BYTES}")
        try:
            parsed = json.loads(body)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            return _error(400, f"malformed JSON in the request body: {exc}")
        return JSONResponse(await run_in_threadpool(service.post_verdict, parsed))

    return [
        Route("/api/batches", batches), Route("/api/trees", trees), Route("/api/trees/{tree_id}", tree),
        Route("/api/trees/{tree_id}/neighbours", neighbours), Route("/api/trees/{tree_id}/glb", glb),
        Route("/api/trees/{tree_id}/skeleton", skeleton),
        Route("/api/trees/{tree_id}/views/{view:int}/{output}", image),
        Route("/api/verdicts", verdicts, methods=["GET", "POST"]),
    ]


def listen_socket(host: str, port: int) -> socket.socket:
    """A TCP socket bound to host:port (0 picks a free port), or a ReviewError naming the address and the cause."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    # Accepted connections inherit this; without it small responses wait ~40 ms for a delayed ACK (Nagle).
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        advice = ("choose another --port" if exc.errno in (errno.EADDRINUSE, errno.EACCES)
                  else "--host must be a name or address of this machine")
        raise ReviewError(f"cannot listen on {host}:{port} ({exc.strerror}): {advice}") from None
    return sock


class ReviewServer:
    """uvicorn serving an app on a socket bound at construction (port 0 picks a free one), in a thread or not.

    sock : a socket from `listen_socket(host, ...)` (bound before anything else is made); port is then its own.
    """

    def __init__(self, app, host: str = "127.0.0.1", port: int = 0, sock: socket.socket | None = None):
        import uvicorn

        self.socket = sock if sock is not None else listen_socket(host, port)
        self.host, self.port = host, self.socket.getsockname()[1]
        self.server = uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off",
                                                    timeout_graceful_shutdown=2))
        self._thread: threading.Thread | None = None

    def url(self, token: str) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/?token={token}"

    @property
    def base(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def run(self) -> None:
        """Serve in this thread until interrupted (Ctrl-C)."""
        self.server.run(sockets=[self.socket])

    def start(self, timeout_s: float = 10.0) -> "ReviewServer":
        """Serve in a background thread; returns once the server accepts connections."""
        self._thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.socket]}, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise ReviewError(f"review server on {self.base} did not start within {timeout_s} s")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10)
        self.socket.close()

    def __enter__(self) -> "ReviewServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
