"""A Starlette app behind an access token, served by uvicorn on a bound socket over HTTP or HTTPS: the pieces the
review server (`farm review`) and the modelling server (`farm model`) share.

In: an ASGI app and a token; out: the app in a token guard, static files served without traversal, a listening
socket that names a taken port in one line, and a server run in this thread or a background one.
"""
from __future__ import annotations

import errno
import hmac
import re
import secrets
import socket
import threading
import time
from pathlib import Path
from urllib.parse import parse_qs

from species.errors import TreefarmError

__all__ = ["ServerError", "NotServed", "TOKEN_HEADER", "new_token", "check_token", "three_root", "page_head",
           "TokenGuard", "error_response", "error_handlers", "safe_file", "static_response", "read_json_body",
           "listen_socket", "TokenServer"]

TOKEN_HEADER = "x-review-token"  # the header name the review client sends; the modelling client sends it too
_TOKEN_PATTERN = re.compile(r"^[A-Za-z0-9_-]{16,128}$")


class ServerError(TreefarmError):
    """A server that cannot start (token, address, certificate) or a request body that cannot be read."""


class NotServed(TreefarmError):
    """A path or object the server does not have (404)."""


def new_token() -> str:
    return secrets.token_urlsafe(24)


def check_token(token: str) -> str:
    if not isinstance(token, str) or not _TOKEN_PATTERN.match(token):
        raise ServerError(f"--token {token!r} is invalid: allowed 16-128 letters, digits, '-' or '_'")
    return token


def three_root() -> Path:
    """three.js in the project's node_modules (served to the web clients under /static/TOKEN/three/)."""
    three = Path(__file__).resolve().parents[1] / "node_modules" / "three"
    if not (three / "build" / "three.module.js").is_file():
        raise ServerError(f"three.js is not installed at {three}: run `make node-env` (npm ci) in the project root")
    return three


def page_head(token: str, title: str, script: str) -> str:
    """The <head> of a served page: the token (meta review-token, which the clients' api.js reads), the client's
    style.css and module `script` under /static/TOKEN/web/, and the import map that resolves 'three' and
    'three/addons/' to /static/TOKEN/three/."""
    static = f"/static/{token}"
    return (f'<head>\n<meta charset="utf-8">\n<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f'<meta name="review-token" content="{token}">\n<link rel="icon" href="data:,">\n<title>{title}</title>\n'
            f'<link rel="stylesheet" href="{static}/web/style.css">\n<script type="importmap">\n'
            f'{{"imports": {{"three": "{static}/three/build/three.module.js",\n'
            f'             "three/addons/": "{static}/three/examples/jsm/"}}}}\n</script>\n'
            f'<script type="module" src="{static}/web/{script}"></script>\n</head>')


def error_handlers(statuses: dict) -> dict:
    """Starlette exception handlers answering each exception class with {"error": message} and its HTTP status
    ({ReviewError: 400, NotServed: 404, PermissionError: 403, ...}; the most specific class wins)."""
    def handler(status: int):
        async def answer(request, exc):
            return error_response(status, str(exc))
        return answer

    return {kind: handler(status) for kind, status in statuses.items()}


def error_response(status: int, message: str):
    from starlette.responses import JSONResponse

    return JSONResponse({"error": message}, status_code=status)


class TokenGuard:
    """ASGI middleware: a request without the right token gets 401 before it reaches any route. The token comes
    in the header TOKEN_HEADER, the query `?token=`, or the `/static/TOKEN/...` path prefix (so ES module imports,
    which cannot set headers, resolve relative to it). `command` names the command whose printed URL to open."""

    def __init__(self, app, token: str, command: str = "farm review"):
        self.app, self.token, self.command = app, token.encode(), command

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
            response = error_response(401, f"missing or wrong access token: open the URL that `{self.command}` "
                                           "printed (it carries ?token=)")
            await response(scope, receive, send)
            return
        await self.app(scope, receive, send)


def safe_file(root: Path, relative: str) -> Path:
    """`relative` under `root`, refusing '..', absolute paths and links that lead outside it (PermissionError)."""
    parts = relative.replace("\\", "/").split("/")
    if relative.startswith("/") or ".." in parts or "\0" in relative:
        raise PermissionError(f"path {relative!r} leads outside the served folder")
    target = (root / relative).resolve()
    if not target.is_relative_to(root.resolve()):
        raise PermissionError(f"path {relative!r} leads outside the served folder")
    if not target.is_file():
        raise NotServed(f"no file {relative!r}")
    return target


def static_response(roots: dict[str, Path], root_name: str, relative: str, fresh: Path):
    """The file `relative` of the served folder `root_name` (JavaScript as text/javascript); files under `fresh`
    (the client's own folder) are revalidated on every load, the rest (three.js) cached for an hour."""
    import mimetypes

    from starlette.responses import Response

    root = roots.get(root_name)
    if root is None:
        raise NotServed(f"no static folder {root_name!r}; folders: {', '.join(roots)}")
    target = safe_file(root, relative)
    media = "text/javascript" if target.suffix in (".js", ".mjs") else mimetypes.guess_type(target.name)[0]
    return Response(target.read_bytes(), media_type=media or "application/octet-stream",
                    headers={"Cache-Control": "max-age=3600" if root != fresh else "no-cache"})


async def read_json_body(request, limit: int, what: str, empty=None):
    """The request's JSON body, or an error response: 413 over `limit` bytes (refused on its Content-Length before
    it is read, else before parsing), 400 when it is not JSON. Returns (parsed, None) or (None, response); an
    empty body is `empty` when that is given."""
    import json

    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit:
        return None, error_response(413, f"{what} body of {int(declared)} bytes; allowed at most {limit}")
    body = await request.body()
    if len(body) > limit:
        return None, error_response(413, f"{what} body of {len(body)} bytes; allowed at most {limit}")
    if empty is not None and not body.strip():
        return empty, None
    try:
        return json.loads(body), None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        return None, error_response(400, f"malformed JSON in the request body: {exc}")


def listen_socket(host: str, port: int) -> socket.socket:
    """A TCP socket bound to host:port (0 picks a free port), or a ServerError naming the address and the cause."""
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
        raise ServerError(f"cannot listen on {host}:{port} ({exc.strerror}): {advice}") from None
    sock.listen()  # connections wait in the backlog from now on, not refused until uvicorn has started
    return sock


class TokenServer:
    """uvicorn serving an app on a socket bound at construction (port 0 picks a free one), in a thread or not.

    sock : a socket from `listen_socket(host, ...)` (bound before anything else is made); port is then its own.
    tls  : (certificate file, key file) for HTTPS, or None for plain HTTP.
    """

    def __init__(self, app, host: str = "127.0.0.1", port: int = 0, sock: socket.socket | None = None,
                 tls: tuple[str, str] | None = None):
        import uvicorn

        self.socket = sock if sock is not None else listen_socket(host, port)
        self.host, self.port = host, self.socket.getsockname()[1]
        self.scheme = "https" if tls else "http"
        certificate = {"ssl_certfile": tls[0], "ssl_keyfile": tls[1]} if tls else {}
        config = uvicorn.Config(app, log_level="warning", lifespan="off", timeout_graceful_shutdown=2, **certificate)
        if tls:
            try:
                config.load()  # reads the certificate now: a bad one is a one-line error, not a thread's traceback
            except (OSError, ValueError) as exc:
                self.socket.close()
                raise ServerError(f"cannot use --tls-cert {tls[0]} with --tls-key {tls[1]}: {exc}") from None
        self.server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    @property
    def base(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"

    def url(self, token: str) -> str:
        return f"{self.base}/?token={token}"

    def run(self) -> None:
        """Serve in this thread until interrupted (Ctrl-C)."""
        self.server.run(sockets=[self.socket])

    def start(self, timeout_s: float = 10.0) -> "TokenServer":
        """Serve in a background thread; returns once the server accepts connections."""
        self._thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.socket]}, daemon=True)
        self._thread.start()
        deadline = time.monotonic() + timeout_s
        while not self.server.started:
            if time.monotonic() > deadline or not self._thread.is_alive():
                raise ServerError(f"server on {self.base} did not start within {timeout_s} s")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=10)
        self.socket.close()

    def __enter__(self) -> "TokenServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
