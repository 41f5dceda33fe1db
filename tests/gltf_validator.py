"""Test helper: run the Khronos glTF validator (npm package gltf-validator, installed by `make env`) on GLB bytes.

`validation_report(data, tmp_path) -> dict` returns the validator's JSON report; `assert_valid_glb` asserts no errors.
"""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

from required_tools import missing_tool

REPO_ROOT = Path(__file__).resolve().parents[1]
SCRIPT = REPO_ROOT / "tests" / "tools" / "validate_gltf.mjs"
PACKAGE = REPO_ROOT / "node_modules" / "gltf-validator"


def validation_report(data: bytes, tmp_path: Path, name: str = "tree.glb") -> dict:
    """The validator's report for `data` (written to tmp_path/name); skips the test when node is missing (fails
    with CI=true), and fails when npm is there but `make env` has not installed the validator."""
    node = shutil.which("node")
    if node is None:
        missing_tool("node is not installed, so the Khronos glTF validator cannot run (apt-get install nodejs)")
    if not PACKAGE.is_dir() and shutil.which("npm") is None:
        missing_tool("npm is not installed, so `make env` could not install gltf-validator (apt-get install npm)")
    if not PACKAGE.is_dir():
        raise AssertionError(f"{PACKAGE} is missing: run `make env` (it runs `npm ci` for the glTF validator)")
    path = tmp_path / name
    path.write_bytes(data)
    done = subprocess.run([node, str(SCRIPT), str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, f"validator failed to run: {done.stderr.strip()}"
    return json.loads(done.stdout)


def assert_valid_glb(data: bytes, tmp_path: Path, name: str = "tree.glb") -> dict:
    """Assert the validator finds zero errors in `data`; returns the report (warnings may be checked by callers)."""
    report = validation_report(data, tmp_path, name)
    issues = report["issues"]
    errors = [m for m in issues["messages"] if m.get("severity") == 0]
    assert issues["numErrors"] == 0, f"glTF validator errors: {json.dumps(errors[:10], indent=1)}"
    return report
