"""pyproject.toml in the form current setuptools reads without a deprecation banner during `pip install -e .`."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

PYPROJECT = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())


def test_the_license_is_an_spdx_expression_and_the_build_reads_it():
    assert PYPROJECT["project"]["license"] == "MIT"  # a {text = ...} table is deprecated: a banner per build step
    (setuptools,) = [r for r in PYPROJECT["build-system"]["requires"] if r.startswith("setuptools")]
    assert int(re.fullmatch(r"setuptools>=(\d+).*", setuptools).group(1)) >= 77  # the first to read the string form
