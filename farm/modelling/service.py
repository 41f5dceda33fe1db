"""The modelling server's state and tools, apart from HTTP: one shared session history with a version that every
edit raises, each tool of the page as a method taking its JSON request, the grown tree of the current version,
saving, loading and sending to the asset library.

Axes: the page works in three.js's frame (Y up); every point that comes in or goes out is turned here, by
`from_page` and `to_page`, and nowhere else. Inside, sessions are treefarm's frame (Z up, metres).
"""
from __future__ import annotations

import re
import threading
from pathlib import Path

import numpy as np

from species.meshing.gltf import Z_UP_TO_Y_UP

from . import session as edits
from .grow import colonization_presets
from .modelled_tree import session_glb
from .session import History, ModelSession, SessionError, new_session, session_from_json, session_to_json

__all__ = ["ModelService", "Overtaken", "from_page", "to_page", "TOOLS", "SESSION_NAME"]

TOOLS = ("stroke", "lobe", "drag-stroke", "drag-surface", "branch", "move", "brush", "growth")
SESSION_NAME = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
# Painted markers the page draws at most (every marker still grows).
SHOWN_MARKERS = 4000
_GLB_CACHE = 8  # grown trees kept by session state, so an undo back to a grown state costs nothing


class Overtaken(SessionError):
    """A grow request for a version that a newer edit has replaced: dropped, not grown (409)."""


def from_page(points) -> np.ndarray:
    """(K, 3) float64: points in three.js's Y-up frame as treefarm's Z-up ones (the inverse of Z_UP_TO_Y_UP)."""
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise SessionError(f"points of shape {array.shape}: allowed a list of [x, y, z] triples")
    return array @ Z_UP_TO_Y_UP


def to_page(points: np.ndarray) -> list:
    """Z-up points as Y-up [x, y, z] lists for three.js."""
    return (np.asarray(points, dtype=np.float64).reshape(-1, 3) @ Z_UP_TO_Y_UP.T).tolist()


def _rotation_from_page(matrix) -> np.ndarray:
    turn = np.asarray(matrix, dtype=np.float64)
    if turn.shape != (3, 3):
        raise SessionError(f"rotation of shape {turn.shape}: allowed a 3 x 3 matrix (rows)")
    return Z_UP_TO_Y_UP.T @ turn @ Z_UP_TO_Y_UP


def _field(body: dict, key: str):
    if key not in body:
        raise SessionError(f"request lacks {key!r}")
    return body[key]


class ModelService:
    """One modelling session shared by every page that opens the server (the later edit wins).

    out     : folder the session files are saved to and loaded from (None: saving to the server is off).
    library : the asset library folder `send to library` builds into (None: off).
    """

    def __init__(self, out: str | Path | None = None, library: str | Path | None = None,
                 session: ModelSession | None = None):
        self.out = Path(out) if out is not None else None
        self.library = str(library) if library is not None else None
        self.history = History(session if session is not None else new_session())
        self.version = 0
        self._lock = threading.Lock()
        self._grow_lock = threading.Lock()
        self._grown: list[tuple[ModelSession, bytes]] = []

    # --- state -------------------------------------------------------------------------------------------------
    def state(self) -> dict:
        """What the page draws: the version, growth settings and every stroke, lobe, branch and brush (Y up)."""
        with self._lock:
            history, version = self.history, self.version
        session = history.present
        markers = session.markers
        step = max(1, -(-len(markers) // SHOWN_MARKERS))
        return {
            "version": version, "preset": session.preset, "presets": colonization_presets(), "seed": session.seed,
            "parameters": session.parameters, "can_undo": bool(history.past), "can_redo": bool(history.future),
            "strokes": [to_page(s) for s in session.strokes],
            "lobes": [{"strokes": [to_page(s) for s in lobe.strokes], "vertices": to_page(lobe.vertices),
                       "faces": lobe.faces.tolist()} for lobe in session.lobes],
            "branches": [{"points": to_page(b.points), "parent": b.parent} for b in session.branches],
            "brushes": [{"path": to_page(b.path), "radius": b.radius, "density": b.density,
                         "markers": len(b.markers)} for b in session.brushes],
            "markers": to_page(markers[::step]), "marker_count": len(markers),
            "saving": self.out is not None, "library": self.library is not None,
        }

    def _commit(self, change) -> dict:
        """Apply `change(History) -> History` under the lock as one new version; a refused change raises and
        leaves history and version as they were."""
        with self._lock:
            self.history = change(self.history)
            self.version += 1
        return self.state()

    # --- tools -------------------------------------------------------------------------------------------------
    def edit(self, tool: str, body: dict) -> dict:
        """Apply one tool's request (JSON object; points Y up) as a new version; returns the new state."""
        if not isinstance(body, dict):
            raise SessionError(f"{tool} request is {type(body).__name__}; allowed a JSON object")
        if tool not in TOOLS:
            raise SessionError(f"unknown tool {tool!r}: allowed {', '.join(TOOLS)}")
        make = getattr(self, "_" + tool.replace("-", "_"))
        return self._commit(lambda history: history.apply(make(history.present, body)))

    def _stroke(self, session, body):
        return edits.add_stroke(session, from_page(_field(body, "points")))

    def _lobe(self, session, body):
        return edits.make_lobe(session, body.get("strokes"), body.get("lobe"))

    def _drag_stroke(self, session, body):
        return edits.drag_stroke(session, _field(body, "lobe"), _field(body, "stroke"), _field(body, "index"),
                                 from_page([_field(body, "target")])[0], body.get("span"))

    def _drag_surface(self, session, body):
        return edits.drag_surface(session, _field(body, "lobe"), _field(body, "handle"),
                                  from_page([_field(body, "target")])[0], _field(body, "radius"))

    def _branch(self, session, body):
        return edits.add_branch(session, from_page(_field(body, "points")))

    def _move(self, session, body):
        rotation = _rotation_from_page(body.get("rotation", np.eye(3).tolist()))
        translation = from_page([body.get("translation", [0.0, 0.0, 0.0])])[0]
        return edits.move_subtree(session, _field(body, "branch"), rotation, translation)

    def _brush(self, session, body):
        return edits.paint(session, from_page(_field(body, "path")), _field(body, "radius"), _field(body, "density"))

    def _growth(self, session, body):
        return edits.set_growth(session, body.get("preset"), body.get("parameters"), body.get("seed"))

    def undo(self) -> dict:
        return self._commit(lambda history: history.undo())

    def redo(self) -> dict:
        return self._commit(lambda history: history.redo())

    # --- growth ------------------------------------------------------------------------------------------------
    def grow(self, version: int) -> tuple[int, bytes]:
        """(version, GLB) of the tree of `version`, which must be the current one: a request a newer edit has
        overtaken, before or while it grows, raises Overtaken and is dropped. One tree grows at a time."""
        with self._grow_lock:
            with self._lock:
                current, session = self.version, self.history.present
            if version != current:
                raise Overtaken(f"grow of version {version} dropped: the session is at version {current}")
            glb = next((data for state, data in self._grown if state is session), None)
            if glb is None:
                glb = session_glb(session)
                self._grown = (self._grown + [(session, glb)])[-_GLB_CACHE:]
        with self._lock:
            if self.version != version:
                raise Overtaken(f"grow of version {version} dropped: a newer edit made version {self.version}")
        return version, glb

    # --- files -------------------------------------------------------------------------------------------------
    def session_json(self) -> str:
        with self._lock:
            return session_to_json(self.history.present)

    def _named(self, name) -> Path:
        if self.out is None:
            raise SessionError("this server saves no files: start `farm model` with --out DIR")
        if not isinstance(name, str) or not SESSION_NAME.match(name):
            raise SessionError(f"session name {name!r} is invalid: allowed 1-64 letters, digits, '-' or '_'")
        return self.out / f"{name}.json"

    def save(self, name: str = "session") -> dict:
        """Write the session to OUT/NAME.json (whole or not at all); returns its path and size."""
        path = self._named(name)
        text = self.session_json()
        partial = path.with_name(f".{path.name}.partial")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            partial.write_text(text)
            partial.replace(path)
        except OSError as exc:
            raise SessionError(f"cannot save the session to {path}: {exc.strerror or exc}") from None
        return {"path": str(path), "bytes": len(text.encode())}

    def load(self, body: dict) -> dict:
        """Load a session as a new version (undo returns to the one before): {"name": NAME} reads OUT/NAME.json,
        anything else is the session record itself."""
        if isinstance(body, dict) and set(body) == {"name"}:
            path = self._named(body["name"])
            try:
                loaded = session_from_json(path.read_bytes())
            except OSError:
                raise SessionError(f"no saved session {body['name']!r} in {self.out}") from None
        else:
            loaded = session_from_json(body)
        return self._commit(lambda history: history.apply(loaded))

    def send_to_library(self) -> dict:
        """Build the session's tree as a studio asset into the library folder; returns the asset's record."""
        from .library_send import send_session_to_library  # the asset builder loads renderers and textures

        if self.library is None:
            raise SessionError("no asset library: start `farm model` with --library DIR")
        with self._lock:
            session = self.history.present
        return send_session_to_library(session, self.library)
