"""The floors of `shared/docs/architecture.md`, read from every module's imports: each package imports only the
floors its "may import" column allows, `species` only the standard library and its own few dependencies, nobody
takes a `_private` name from another package, and no import inside a function dodges a cycle of our modules."""
from __future__ import annotations

import ast
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT_PACKAGES = ("species", "renderers", "farm", "trainers", "reconstruct")
# Beside the product: what tests and benchmarks share (fixtures), and the two that use it without importing
# each other.
SUPPORT_FOLDERS = ("fixtures", "tests", "benchmarks")
CHECKED_FOLDERS = PROJECT_PACKAGES + SUPPORT_FOLDERS

# The dataset-format floor inside `farm`, named by its package: what trainers and reconstruct may read shards with.
FARM_FORMAT = "farm.dataset"
# floor -> the floors it may import ("may import" column of the architecture table).
MAY_IMPORT = {
    "species": {"species"},
    "renderers": {"species", "renderers"},
    "farm-format": {"species", "farm-format"},
    "trainers": {"species", "farm-format", "trainers"},
    "reconstruct": {"species", "renderers", "trainers", "farm-format", "reconstruct"},
    "farm": {"species", "renderers", "farm-format", "trainers", "reconstruct", "farm"},
    "fixtures": {"species", "fixtures"},
    "tests": None,  # everything
    "benchmarks": {"species", "renderers", "farm-format", "trainers", "reconstruct", "farm", "fixtures", "benchmarks"},
}
# Besides the standard library, what `species` may import: nothing knows of Ray, Parquet, torch or a renderer.
SPECIES_THIRD_PARTY = {"numpy", "scipy", "trimesh", "PIL", "cv2"}
# Besides the standard library, what the dataset format may import: arrays, Parquet, images, and the libraries its
# readers hand a table to (each imported where that reader is used). Not Ray: its reader is `farm.ray_data`.
FORMAT_THIRD_PARTY = {"numpy", "pyarrow", "PIL", "cv2", "duckdb", "datasets", "torch"}
THIRD_PARTY = {"species": SPECIES_THIRD_PARTY, "farm-format": FORMAT_THIRD_PARTY}


@dataclass(frozen=True)
class Import:
    source: str        # importing module, dotted ("farm.library.job")
    path: str          # its file, relative to the repository root
    line: int
    target: str        # imported module, dotted and absolute
    names: tuple[str, ...]  # names taken from it (empty for `import x`)
    in_function: bool


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def floor_of(module: str) -> str | None:
    top = module.split(".")[0]
    if module == FARM_FORMAT or module.startswith(FARM_FORMAT + "."):
        return "farm-format"
    return top if top in MAY_IMPORT else None


def _resolve(source: str, is_package: bool, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = source.split(".") if is_package else source.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(path: Path, text: str | None = None, known_modules: set[str] = frozenset()) -> list[Import]:
    """Every import statement of one file, relative imports resolved; `from pkg import module` names the module."""
    source = module_name(path)
    tree = ast.parse(text if text is not None else path.read_text(), str(path))
    is_package = path.name == "__init__.py"
    function_lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            function_lines.update(n.lineno for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom)))
    relative = str(path.relative_to(ROOT))
    found = []
    for node in ast.walk(tree):
        inside = getattr(node, "lineno", 0) in function_lines
        if isinstance(node, ast.Import):
            found += [Import(source, relative, node.lineno, alias.name, (), inside) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module != "__future__":
            target = _resolve(source, is_package, node)
            for alias in node.names:
                submodule = f"{target}.{alias.name}"
                if submodule in known_modules:
                    found.append(Import(source, relative, node.lineno, submodule, (), inside))
                else:
                    found.append(Import(source, relative, node.lineno, target, (alias.name,), inside))
    return found


def project_files() -> list[Path]:
    files = []
    for folder in CHECKED_FOLDERS:
        files += sorted(p for p in (ROOT / folder).rglob("*.py") if ".venv" not in p.parts)
    return files


@pytest.fixture(scope="module")
def all_imports() -> list[Import]:
    files = project_files()
    known = {module_name(p) for p in files}
    return [imp for path in files for imp in imports_of(path, known_modules=known)]


def _package(module: str, is_package: bool = False) -> str:
    return module if is_package else module.rpartition(".")[0]


def _defining_package(module: str) -> str:
    """The package a module's names belong to: the module itself when it is a package's __init__."""
    return _package(module, (ROOT / module.replace(".", "/") / "__init__.py").is_file())


def floor_violations(imports: list[Import]) -> list[str]:
    out = []
    for imp in imports:
        floor, allowed = floor_of(imp.source), MAY_IMPORT.get(floor_of(imp.source) or "")
        target_top = imp.target.split(".")[0]
        if floor is None or allowed is None:
            continue
        if target_top in CHECKED_FOLDERS:
            target_floor = floor_of(imp.target)
            if target_floor not in allowed:
                out.append(f"{imp.path}:{imp.line}: {imp.source} ({floor}) imports {imp.target} ({target_floor}); "
                           f"{floor} may import {', '.join(sorted(allowed))}")
        elif floor in THIRD_PARTY and target_top not in sys.stdlib_module_names | THIRD_PARTY[floor]:
            out.append(f"{imp.path}:{imp.line}: {imp.source} imports {imp.target}; {floor} may import the standard "
                       f"library and {', '.join(sorted(THIRD_PARTY[floor]))}")
    return out


def private_violations(imports: list[Import]) -> list[str]:
    """`_name`s (or `_module`s) of our packages taken from outside the package that defines them."""
    out = []
    for imp in imports:
        if imp.target.split(".")[0] not in PROJECT_PACKAGES:
            continue
        importer_package = _package(imp.source, imp.path.endswith("__init__.py"))
        private_modules = [p for p in imp.target.split(".") if p.startswith("_") and not p.startswith("__")]
        target_package = _defining_package(imp.target) if imp.names else _package(imp.target)
        private_names = [n for n in imp.names if n.startswith("_") and not n.startswith("__")]
        if (private_names or private_modules) and target_package != importer_package:
            taken = ", ".join(private_names or private_modules)
            out.append(f"{imp.path}:{imp.line}: {imp.source} takes private {taken} from {imp.target}; make it public "
                       "where it lives")
    return out


def cycle_dodges(imports: list[Import]) -> list[str]:
    """Imports inside a function of one of our modules that imports the importer back (at any level)."""
    graph: dict[str, set[str]] = {}
    for imp in imports:
        if imp.target.split(".")[0] in PROJECT_PACKAGES:
            graph.setdefault(imp.source, set()).add(imp.target)

    def reaches(start: str, goal: str) -> bool:
        seen, todo = set(), [start]
        while todo:
            node = todo.pop()
            if node == goal:
                return True
            if node not in seen:
                seen.add(node)
                todo.extend(graph.get(node, ()))
        return False

    found = {f"{imp.path}:{imp.line}: {imp.source} imports {imp.target} inside a function, and {imp.target} imports "
             f"{imp.source} back: break the cycle" for imp in imports
             if imp.in_function and imp.target.split(".")[0] in PROJECT_PACKAGES and imp.target != imp.source
             and reaches(imp.target, imp.source)}
    return sorted(found)


def test_every_import_stays_on_the_floors_the_architecture_allows(all_imports):
    problems = floor_violations(all_imports)
    assert not problems, "\n".join(problems)


def test_no_module_takes_a_private_name_from_another_package(all_imports):
    problems = private_violations(all_imports)
    assert not problems, "\n".join(problems)


def test_no_import_inside_a_function_dodges_a_cycle(all_imports):
    problems = cycle_dodges(all_imports)
    assert not problems, "\n".join(problems)


# ---------------------------------------------------------------------- the checks themselves catch what they name
def _imports(relative: str, text: str, known: set[str] = frozenset()) -> list[Import]:
    return imports_of(ROOT / relative, text, known)


@pytest.mark.parametrize("relative, text", [
    ("trainers/fit.py", "from renderers import ViewRenderer\n"),
    ("reconstruct/job.py", "def run():\n    from farm.pipeline import run_job\n"),
    ("farm/dataset/schema.py", "import farm.review.server\n"),
    ("species/skeleton.py", "import ray\n"),
    ("species/meshing/gltf.py", "from pyarrow import parquet\n"),
    ("species/studio/lod.py", "import torch\n"),
    ("species/geometry/frames.py", "from pyrender import Mesh\n"),
    ("species/__init__.py", "import bpy\n"),
    ("farm/dataset/readers.py", "import trimesh\n"),
    ("farm/dataset/readers.py", "def to_ray():\n    import ray.data\n"),
    ("farm/dataset/schema.py", "from renderers import OUTPUTS\n"),
    ("renderers/views.py", "from ..farm.jobs import JobSpec\n"),
    ("benchmarks/bench_mesh.py", "from tests.species.test_mesh import random_tree\n"),
    ("fixtures/skeletons.py", "from farm.pipeline import run_job\n"),
    ("farm/pipeline.py", "from fixtures.skeletons import random_tree\n"),
])
def test_an_import_off_the_floors_is_named_with_its_line(relative, text):
    problems = floor_violations(_imports(relative, text))
    assert len(problems) == 1 and problems[0].startswith(f"{relative}:")


def test_allowed_imports_pass_the_floor_check():
    allowed = [("trainers/fit.py", "import torch\nfrom farm.dataset import open\nimport species\n"),
               ("reconstruct/job.py", "from renderers import ViewRenderer\nfrom trainers import fit\n"),
               ("species/meshing/textures.py", "import numpy\nfrom PIL import Image\nimport cv2, zlib\n"),
               ("farm/pipeline.py", "import ray\nfrom farm.library import job\n"),
               ("benchmarks/bench_mesh.py", "from fixtures.skeletons import random_tree\nfrom farm.table import x\n"),
               ("tests/species/test_mesh.py", "from fixtures.skeletons import random_tree\n")]
    for relative, text in allowed:
        assert floor_violations(_imports(relative, text)) == [], relative


def test_private_names_are_caught_across_packages_only():
    across = _imports("farm/library/spec.py", "from farm.jobs import _check_int, load_spec\n")
    assert private_violations(across) == [
        "farm/library/spec.py:1: farm.library.spec takes private _check_int from farm.jobs; make it public where "
        "it lives"]
    relative = _imports("renderers/impostor.py", "from .maps import _single_sample_renderer_class\n")
    assert private_violations(relative) == []
    private_module = _imports("farm/pipeline.py", "from species.meshing import _atlas\n",
                              {"species.meshing._atlas"})
    assert len(private_violations(private_module)) == 1


def test_a_function_level_import_that_closes_a_cycle_is_caught():
    known = {"farm.library.catalog", "farm.library.job"}
    imports = (_imports("farm/library/catalog.py", "def f():\n    from .job import run\n", known)
               + _imports("farm/library/job.py", "from .catalog import write\n", known))
    assert len(cycle_dodges(imports)) == 1
    lazy_only = _imports("farm/commands/generate.py", "def run():\n    from farm.pipeline import run_job\n")
    assert cycle_dodges(lazy_only) == []
