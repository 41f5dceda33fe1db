"""The three.js wind example in a library folder: `wind_example.html` at the root and, when the project's
node_modules holds the pinned three.js, the modules it imports under `viewer/three/` (else it imports them from unpkg).

In: a library Location; out: those files, each written atomically, the same bytes on every run (same checkout).
"""
from __future__ import annotations

import json
from pathlib import Path

from species.errors import TreefarmError

from ..dataset.storage import Location

__all__ = ["WIND_PAGE", "VIEWER_THREE", "THREE_FILES", "three_version", "three_source", "wind_page_html",
           "write_wind_viewer", "wind_link"]

WIND_PAGE = "wind_example.html"
VIEWER_THREE = "viewer/three"
# What the page imports: three itself (three.module.js imports three.core.js), the GLTFLoader and the two
# helpers it imports, and OrbitControls. Paths inside the three package, kept as they are so relative imports hold.
THREE_FILES = ("build/three.module.js", "build/three.core.js", "examples/jsm/loaders/GLTFLoader.js",
               "examples/jsm/utils/BufferGeometryUtils.js", "examples/jsm/utils/SkeletonUtils.js",
               "examples/jsm/controls/OrbitControls.js")
_PROJECT = Path(__file__).resolve().parents[2]
_TEMPLATE = Path(__file__).with_name(WIND_PAGE)


class WindViewerError(TreefarmError):
    """The project's three.js pin cannot be read, or node_modules holds another version than the pin."""


def three_version(project: Path = _PROJECT) -> str:
    """The three.js version the project pins: `dependencies.three` in its package.json (the one place it is
    written; the review client and this example both use it)."""
    path = project / "package.json"
    if not path.is_file():
        raise WindViewerError(f"{path} is missing: the wind example takes its three.js version from it")
    version = json.loads(path.read_text()).get("dependencies", {}).get("three")
    if not isinstance(version, str) or not version:
        raise WindViewerError(f"{path} pins no three.js version (dependencies.three): allowed a version string")
    return version


def three_source(project: Path = _PROJECT) -> Path | None:
    """node_modules/three when `make node-env` installed the pinned version there, None when it is absent.
    A different installed version is an error (a stale `npm ci`), not a quiet switch to unpkg."""
    folder = project / "node_modules" / "three"
    if not (folder / "package.json").is_file():
        return None
    installed = json.loads((folder / "package.json").read_text())["version"]
    pinned = three_version(project)
    if installed != pinned:
        raise WindViewerError(f"node_modules holds three {installed} but package.json pins {pinned}: run "
                              f"`make node-env` (npm ci)")
    missing = [name for name in THREE_FILES if not (folder / name).is_file()]
    if missing:
        raise WindViewerError(f"three {installed} in {folder} lacks {', '.join(missing)}: run `make node-env`")
    return folder


def wind_page_html(local: bool, version: str) -> str:
    """The page with its import map: `viewer/three/...` beside it when `local`, else unpkg at `version`."""
    if local:
        base = f"./{VIEWER_THREE}/"
        note = f"three.js {version}, copied from the project's node_modules into {VIEWER_THREE}/"
    else:
        base = f"https://unpkg.com/three@{version}/"
        note = f"three.js {version} from unpkg (needs the network)"
    imports = {"three": f"{base}build/three.module.js", "three/addons/": f"{base}examples/jsm/"}
    page = _TEMPLATE.read_text()
    for placeholder in ("{{IMPORTMAP}}", "{{THREE_SOURCE}}"):
        if placeholder not in page:
            raise WindViewerError(f"{_TEMPLATE} lacks the placeholder {placeholder}")
    return page.replace("{{IMPORTMAP}}", json.dumps({"imports": imports})).replace("{{THREE_SOURCE}}", note)


def write_wind_viewer(location: Location, project: Path = _PROJECT) -> dict:
    """Write wind_example.html (and the three.js files it imports, when node_modules has them) into the
    library; returns {"page": relative path, "three": "local" | "unpkg", "version": str}."""
    version = three_version(project)
    folder = three_source(project)
    for name in THREE_FILES if folder is not None else ():
        location.write_atomic(f"{VIEWER_THREE}/{name}", (folder / name).read_bytes())
    location.write_atomic(WIND_PAGE, wind_page_html(folder is not None, version).encode())
    return {"page": WIND_PAGE, "three": "unpkg" if folder is None else "local", "version": version}


def wind_link(glb_path: str) -> str:
    """The page's URL (relative to the library root) showing the GLB at `glb_path` (relative to the root)."""
    from urllib.parse import quote

    return f"{WIND_PAGE}?glb={quote(glb_path, safe='/')}"
