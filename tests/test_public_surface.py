"""The packages' public surfaces: each name in `farm`, `trainers` and `farm.evaluate`'s `__all__` resolves, and
importing `farm` and `trainers` (what `farm --help` starts from) pulls in neither Ray, torch, pyrender nor MLflow."""
from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("ray", "torch", "pyrender", "mlflow")


def _heavy_modules_after(code: str) -> list[str]:
    """The HEAVY modules loaded by a fresh interpreter once it has run `code`."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"
    done = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_importing_farm_and_trainers_loads_no_heavy_dependency():
    assert _heavy_modules_after("import farm, trainers") == []


def test_the_command_lines_parser_loads_no_heavy_dependency():
    assert _heavy_modules_after("from farm.cli import build_parser\nbuild_parser().format_help()") == []


@pytest.mark.parametrize("package", ["farm", "trainers", "farm.evaluate"])
def test_every_public_name_resolves(package):
    module = importlib.import_module(package)
    assert module.__all__ and len(set(module.__all__)) == len(module.__all__)
    missing = [name for name in module.__all__ if getattr(module, name, None) is None]
    assert not missing, missing


@pytest.mark.parametrize("package", ["farm", "trainers"])
def test_an_unknown_name_is_an_attribute_error(package):
    with pytest.raises(AttributeError, match="no_such_name"):
        getattr(importlib.import_module(package), "no_such_name")
