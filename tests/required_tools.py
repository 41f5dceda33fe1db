"""Test helper: a tool the README's environment provides (node, the glTF validator, Chromium, three.js) is missing.

Outside CI the test skips with the command that installs it; with `CI=true` (set by `.ci/run`) it fails, so
"every GLB is validated" and "the page runs in a real browser" hold wherever the README says they do.
"""
from __future__ import annotations

import os

import pytest


def in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() == "true"


def missing_tool(reason: str, allow_module_level: bool = False) -> None:
    """Skip (or, in CI, fail) the calling test because a tool is missing; `reason` says how to install it."""
    if in_ci():
        pytest.fail(f"{reason} (CI=true: the tests need every tool `make env` installs)", pytrace=False)
    pytest.skip(reason, allow_module_level=allow_module_level)
