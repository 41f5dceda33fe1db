"""The modelling session: what a modeller has made (strokes, crown lobes, main branches, painted markers) and how
it grows (a colonization preset, parameter overrides, a seed); each edit is a function from one state to a new
one, with undo and redo over them, and the session's JSON file.

In: points in metres, Z up, float64 (the page's Y-up points are turned at the server's edge). Out: new
`ModelSession`s (a state is never changed in place; a refused edit raises `SessionError` and changes nothing) and
the session JSON, which loads back to the same state, array for array.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field, replace

import numpy as np
import trimesh

from species.errors import TreefarmError

from .branch_moves import guarded_move
from .brush import brush_markers
from .grow import colonization_presets, model_params
from .lobes import Lobe
from .strokes import sample_stroke
from .surface_edit import bezier_drag

__all__ = ["SessionError", "DrawnLobe", "Branch", "BrushStroke", "ModelSession", "History", "new_session",
           "add_stroke", "make_lobe", "drag_stroke", "drag_surface", "add_branch", "move_subtree", "paint",
           "set_growth", "session_to_json", "session_from_json", "FORMAT", "FORMAT_VERSION",
           "GROW_LIMITS", "MAX_PAINTED_MARKERS", "DEFAULT_PRESET"]

FORMAT = "treefarm-model-session"
FORMAT_VERSION = 1
DEFAULT_PRESET = "sc_round_maple"
# A grow request above these is refused: growth time rises with both, and the page waits for every grow.
GROW_LIMITS = {"max_markers": 30000, "iterations": 80}
MAX_PAINTED_MARKERS = 20000
# A branch drawn from within this distance of another branch grows from it; farther, it grows from the ground.
ATTACH_DISTANCE_M = 0.5
MAX_UNDO = 200


class SessionError(TreefarmError):
    """An edit the session refuses (the message says why and what is allowed), or a file that is not a session."""


def _frozen(values, columns: int | None = 3, dtype=np.float64) -> np.ndarray:
    array = np.array(values, dtype=dtype)
    if columns is not None and (array.ndim != 2 or array.shape[1] != columns):
        raise SessionError(f"points of shape {array.shape}: allowed a list of [x, y, z] triples")
    if dtype == np.float64 and not np.isfinite(array).all():
        raise SessionError("points hold NaN or infinite coordinates: allowed finite metres")
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class DrawnLobe:
    """A crown lobe: its strokes, which are its whole state (a surface drag moves their samples), and the closed
    mesh they make.

    strokes  : tuple of (k, 3) float64, metres, Z up (sampled strokes, read-only).
    vertices : (V, 3) float64, metres, Z up; faces: (F, 3) int64, outward oriented.
    builder  : the `lobes.Lobe` that meshed it, whose strips the next edit of this lobe reuses (an edit rebuilds
               only the strips next to the stroke it changes); None for a loaded lobe.
    """

    strokes: tuple
    vertices: np.ndarray
    faces: np.ndarray
    builder: object = field(default=None, compare=False, repr=False)

    def mesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(np.array(self.vertices), np.array(self.faces), process=False)


@dataclass(frozen=True)
class Branch:
    """A main branch: points (k, 3) float64 metres Z up from its base; parent: the branch it grows from (-1: the
    ground)."""

    points: np.ndarray
    parent: int


@dataclass(frozen=True)
class BrushStroke:
    """One brush stroke: its path (k, 3), the brush radius (m) and density (markers per m^3), and the markers
    (m, 3) it spawned (float64, metres, Z up), kept so a loaded session grows the same tree."""

    path: np.ndarray
    radius: float
    density: float
    markers: np.ndarray


@dataclass(frozen=True)
class ModelSession:
    """One state of a modelling session. `strokes` are drawn strokes not yet made into a lobe."""

    preset: str = DEFAULT_PRESET
    seed: int = 0
    parameters: dict = field(default_factory=dict)
    strokes: tuple = ()
    lobes: tuple = ()
    branches: tuple = ()
    brushes: tuple = ()

    @property
    def markers(self) -> np.ndarray:
        """(M, 3) float64 every painted marker, brush stroke by brush stroke."""
        parts = [b.markers for b in self.brushes]
        return np.concatenate(parts) if parts else np.zeros((0, 3))


def new_session(preset: str = DEFAULT_PRESET, seed: int = 0) -> ModelSession:
    return set_growth(ModelSession(), preset=preset, seed=seed)


def _sampled(points, what: str) -> np.ndarray:
    try:
        return _frozen(sample_stroke(_frozen(points)))
    except TreefarmError as exc:
        raise SessionError(f"{what}: {exc}") from None


def _index(value, count: int, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < count:
        raise SessionError(f"{what} {value!r} does not exist: allowed an index in [0, {count})")
    return value


def _builder(lobe: DrawnLobe) -> Lobe:
    return lobe.builder if lobe.builder is not None else Lobe.from_strokes(lobe.strokes)


def _meshed(change, refusal: str) -> DrawnLobe:
    """The lobe `change()` (a `lobes.Lobe`) makes, meshed; SessionError starting with `refusal` when it cannot."""
    try:
        builder = change()
        mesh = builder.mesh()
    except TreefarmError as exc:
        raise SessionError(f"{refusal}: {exc}") from None
    return DrawnLobe(builder.strokes, _frozen(mesh.vertices), _frozen(mesh.faces, dtype=np.int64), builder)


def add_stroke(session: ModelSession, points) -> ModelSession:
    """Draw a stroke (a lobe's outline): sampled sparsely and joined by Hermite curves, kept until a lobe uses it."""
    return replace(session, strokes=session.strokes + (_sampled(points, "stroke"),))


def make_lobe(session: ModelSession, strokes=None, lobe: int | None = None) -> ModelSession:
    """Make a lobe from drawn strokes (indices; default all of them), or, with `lobe`, add them to that lobe
    (only the strips next to them are built). The strokes used leave the list of drawn strokes."""
    chosen = list(range(len(session.strokes))) if strokes is None else list(strokes)
    for i in chosen:
        _index(i, len(session.strokes), "stroke")
    if len(set(chosen)) != len(chosen) or not chosen:
        raise SessionError(f"strokes {chosen}: allowed distinct indices of drawn strokes, at least one")
    new = tuple(session.strokes[i] for i in chosen)
    kept = tuple(s for i, s in enumerate(session.strokes) if i not in chosen)
    refusal = "these strokes cannot make a lobe"
    if lobe is None:
        return replace(session, strokes=kept, lobes=session.lobes + (_meshed(lambda: Lobe.from_strokes(new), refusal),))
    _index(lobe, len(session.lobes), "lobe")
    lobes = list(session.lobes)
    base = _builder(lobes[lobe])
    lobes[lobe] = _meshed(lambda: Lobe.from_strokes(base.strokes + new, reuse=base), refusal)
    return replace(session, strokes=kept, lobes=tuple(lobes))


def drag_stroke(session: ModelSession, lobe: int, stroke: int, index: int, target, span=None) -> ModelSession:
    """Drag point `index` of a lobe's stroke to `target`, the span reshaped as a quadratic Bezier (eq. 5.2); the
    strips next to that stroke are rebuilt."""
    _index(lobe, len(session.lobes), "lobe")
    base = _builder(session.lobes[lobe])
    _index(stroke, len(base.strokes), "stroke")
    _index(index, len(base.strokes[stroke]), "stroke point")
    point = _frozen([target])[0]
    lobes = list(session.lobes)
    lobes[lobe] = _meshed(lambda: base.replace_stroke(stroke, bezier_drag(base.strokes[stroke], index, point, span)),
                          "stroke drag refused")
    return replace(session, lobes=tuple(lobes))


def drag_surface(session: ModelSession, lobe: int, handle: int, target, radius: float) -> ModelSession:
    """Drag the lobe's surface at vertex `handle` (its nearest stroke sample) towards `target` by Laplacian
    editing (eq. 5.3-5.5): the handle moves by (target - vertex), vertices farther than `radius` metres along the
    surface stay, and the moved samples move their strokes (`lobes.Lobe.edit_surface`)."""
    _index(lobe, len(session.lobes), "lobe")
    old = session.lobes[lobe]
    _index(handle, len(old.vertices), "lobe vertex")
    if isinstance(radius, bool) or not isinstance(radius, (int, float)) or not radius > 0:
        raise SessionError(f"radius {radius!r} is invalid: allowed a positive number of metres")
    base, point = _builder(old), _frozen([target])[0]
    lobes = list(session.lobes)
    lobes[lobe] = _meshed(lambda: base.edit_surface(old.vertices[handle], point, float(radius)), "surface drag refused")
    return replace(session, lobes=tuple(lobes))


def _nearest_branch(branches: tuple, point: np.ndarray) -> tuple[int, np.ndarray]:
    """(index, nearest point on it) of the branch polyline nearest `point`, or (-1, point) beyond ATTACH_DISTANCE_M."""
    best, best_point, best_distance = -1, point, ATTACH_DISTANCE_M
    for i, branch in enumerate(branches):
        a, b = branch.points[:-1], branch.points[1:]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", point - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12), 0, 1)
        nearest = a + t[:, None] * ab
        distance = np.linalg.norm(nearest - point, axis=1)
        k = int(np.argmin(distance))
        if distance[k] < best_distance:
            best, best_point, best_distance = i, nearest[k], distance[k]
    return best, best_point


def add_branch(session: ModelSession, points) -> ModelSession:
    """Draw a main branch from its base: one starting within ATTACH_DISTANCE_M of a branch grows from it (its
    base snapped onto it), any other from the ground."""
    sampled = _sampled(points, "branch")
    parent, base = _nearest_branch(session.branches, sampled[0])
    if parent >= 0:
        sampled = _frozen(np.vstack([base, sampled[1:]]))
    return replace(session, branches=session.branches + (Branch(sampled, parent),))


def move_subtree(session: ModelSession, branch: int, rotation, translation) -> ModelSession:
    """Turn a branch and everything growing from it rigidly about its base (`rotation`: (3, 3) proper rotation)
    and move it by `translation` (3,) metres; refused (`branch_moves.guarded_move`) when the moved branches'
    convex hulls would touch a branch that stays."""
    _index(branch, len(session.branches), "branch")
    drawn = [(np.array(b.points), b.parent) for b in session.branches]
    try:
        moved = guarded_move(drawn, branch, np.asarray(rotation, np.float64), session.branches[branch].points[0],
                             _frozen([translation])[0])
    except TreefarmError as exc:
        raise SessionError(f"move refused: {exc}") from None
    branches = tuple(old if np.array_equal(old.points, points) else Branch(_frozen(points), old.parent)
                     for old, (points, _) in zip(session.branches, moved))
    return replace(session, branches=branches)


def paint(session: ModelSession, path, radius: float, density: float) -> ModelSession:
    """Paint growth markers in a sphere of `radius` metres round each point of `path`, `density` per m^3 (the
    buds colonize them, steered along the path). The brush's generator is seeded from the session seed and the
    stroke's number, so a replayed session paints the same markers."""
    trail = _frozen(path)
    if len(trail) < 1:
        raise SessionError("a brush stroke needs at least one point")
    for name, value, high in (("radius", radius, 5.0), ("density", density, 5000.0)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= high:
            raise SessionError(f"brush {name} {value!r} is invalid: allowed a number in (0, {high}]")
    rng = np.random.default_rng([session.seed, len(session.brushes)])
    try:
        markers = _frozen(brush_markers(np.array(trail), float(radius), float(density), rng))
    except TreefarmError as exc:
        raise SessionError(f"brush stroke refused: {exc}") from None
    total = len(session.markers) + len(markers)
    if total > MAX_PAINTED_MARKERS:
        raise SessionError(f"this brush stroke makes {total} painted markers; allowed at most {MAX_PAINTED_MARKERS} "
                           "(a smaller brush, a lower density, or undo a stroke)")
    brush = BrushStroke(trail, float(radius), float(density), markers)
    return replace(session, brushes=session.brushes + (brush,))


def set_growth(session: ModelSession, preset: str | None = None, parameters: dict | None = None,
               seed: int | None = None) -> ModelSession:
    """Choose the colonization preset, the parameter overrides (JSON values by schema key; limits: GROW_LIMITS)
    and the seed; unchanged where None."""
    preset = session.preset if preset is None else preset
    known = colonization_presets()
    if preset not in known:
        raise SessionError(f"preset {preset!r} is unknown: allowed {', '.join(known)}")
    parameters = dict(session.parameters if parameters is None else parameters)
    if not isinstance(parameters, dict) or "seed" in parameters:
        raise SessionError("parameters must be a JSON object of colonization parameters without \"seed\" (the "
                           "session's seed is its own field)")
    try:
        model_params(preset, parameters)
    except TreefarmError as exc:
        raise SessionError(f"parameters refused: {exc}") from None
    for key, high in GROW_LIMITS.items():
        if parameters.get(key, 0) > high:
            raise SessionError(f"{key} = {parameters[key]} is over the modelling limit: allowed at most {high}")
    seed = session.seed if seed is None else seed
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise SessionError(f"seed {seed!r} is invalid: allowed an integer in [0, 2^63)")
    return replace(session, preset=preset, parameters=parameters, seed=seed)


@dataclass(frozen=True)
class History:
    """A session with its undo and redo stacks; every edit and every undo or redo makes a new History."""

    present: ModelSession = field(default_factory=ModelSession)
    past: tuple = ()
    future: tuple = ()

    def apply(self, session: ModelSession) -> "History":
        return History(session, (self.past + (self.present,))[-MAX_UNDO:], ())

    def undo(self) -> "History":
        if not self.past:
            raise SessionError("nothing to undo")
        return History(self.past[-1], self.past[:-1], (self.present,) + self.future)

    def redo(self) -> "History":
        if not self.future:
            raise SessionError("nothing to redo")
        return History(self.future[0], self.past + (self.present,), self.future[1:])


def _rows(array: np.ndarray) -> list:
    return np.asarray(array).tolist()  # float64 -> Python float: JSON writes the shortest exact decimal


def session_to_json(session: ModelSession) -> str:
    """The session file: format name and version, growth settings, and every stroke, lobe, branch and brush."""
    record = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "preset": session.preset, "seed": session.seed,
        "parameters": session.parameters, "strokes": [_rows(s) for s in session.strokes],
        "lobes": [{"strokes": [_rows(s) for s in lobe.strokes], "vertices": _rows(lobe.vertices),
                   "faces": _rows(lobe.faces)} for lobe in session.lobes],
        "branches": [{"points": _rows(b.points), "parent": b.parent} for b in session.branches],
        "brushes": [{"path": _rows(b.path), "radius": b.radius, "density": b.density, "markers": _rows(b.markers)}
                    for b in session.brushes],
    }
    return json.dumps(record, indent=1, sort_keys=True, allow_nan=False)


def session_from_json(text: str | bytes | dict) -> ModelSession:
    """A session from its file's text (or parsed record); SessionError when it is not a session file, comes from
    a newer format, or holds a bad value (named)."""
    try:
        record = json.loads(text) if isinstance(text, (str, bytes)) else text
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SessionError(f"not a modelling session file: not JSON ({exc})") from None
    if not isinstance(record, dict) or record.get("format") != FORMAT:
        raise SessionError(f"not a modelling session file: its \"format\" is not {FORMAT!r}")
    version = record.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise SessionError(f"session format_version {version!r} is invalid: allowed an integer from 1")
    if version > FORMAT_VERSION:
        raise SessionError(f"this session file has format version {version}, made by a newer treefarm; this one "
                           f"reads up to version {FORMAT_VERSION}: update treefarm to open it")
    try:
        lobes = tuple(DrawnLobe(tuple(_frozen(s) for s in lobe["strokes"]), _frozen(lobe["vertices"]),
                           _frozen(lobe["faces"], dtype=np.int64)) for lobe in record["lobes"])
        branches = tuple(Branch(_frozen(b["points"]), int(b["parent"])) for b in record["branches"])
        brushes = tuple(BrushStroke(_frozen(b["path"]), float(b["radius"]), float(b["density"]),
                                    _frozen(b["markers"]) if b["markers"] else _frozen(np.zeros((0, 3))))
                        for b in record["brushes"])
        strokes = tuple(_frozen(s) for s in record["strokes"])
        growth = (record["preset"], record["parameters"], record["seed"])
    except (KeyError, TypeError, ValueError) as exc:
        raise SessionError(f"session file is damaged: {type(exc).__name__} {exc}") from None
    for i, branch in enumerate(branches):
        if not -1 <= branch.parent < i:
            raise SessionError(f"session file is damaged: branch {i} grows from branch {branch.parent}, which is "
                               "not an earlier branch")
    for lobe in lobes:
        if lobe.faces.size and (lobe.faces.min() < 0 or lobe.faces.max() >= len(lobe.vertices)):
            raise SessionError("session file is damaged: a lobe face names a vertex it does not have")
    session = ModelSession(strokes=strokes, lobes=lobes, branches=branches, brushes=brushes)
    return set_growth(session, *growth)
