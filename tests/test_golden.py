"""Golden outputs: every preset's tree, the TreeSketchNet dictionaries, a small job's part files and a one-asset
library are byte-identical to the digests in `tests/golden/` (rewritten by `make golden` when outputs change on
purpose). A mismatch names what changed and any dependency whose version differs from the goldens'."""
from __future__ import annotations

import pytest

from golden import goldens


def mismatch_report(name: str, expected: dict, found: dict, found_versions: dict) -> str:
    changed = sorted(k for k in expected["digests"].keys() | found.keys()
                     if expected["digests"].get(k) != found.get(k))
    lines = [f"golden {name!r}: {len(changed)} of {len(expected['digests'])} outputs differ: "
             + ", ".join(changed[:12]) + (" ..." if len(changed) > 12 else "")]
    moved = {k: (v, found_versions.get(k)) for k, v in expected["versions"].items() if found_versions.get(k) != v}
    if moved:
        lines.append("dependency versions differ from the goldens': "
                     + "; ".join(f"{k} {now} (goldens made with {then})" for k, (then, now) in sorted(moved.items())))
    else:
        lines.append("every dependency version is the goldens' own: the code changed these outputs "
                     "(if on purpose, run `make golden` and say so in the commit message)")
    return "\n".join(lines)


@pytest.fixture(scope="module")
def found_versions():
    return goldens.versions()


@pytest.mark.slow
@pytest.mark.parametrize("name", list(goldens.GOLDENS))
def test_outputs_match_their_golden_digests(name, tmp_path, found_versions):
    expected = goldens.load(name)
    found = goldens.compute(name, tmp_path)
    assert found == expected["digests"], mismatch_report(name, expected, found, found_versions)


def test_a_mismatch_report_names_the_changed_outputs_and_moved_versions():
    expected = {"digests": {"a": "1", "b": "2"}, "versions": {"numpy": "2.4.6", "mesa": "22"}}
    report = mismatch_report("x", expected, {"a": "1", "b": "3"}, {"numpy": "2.5.0", "mesa": "22"})
    assert "1 of 2 outputs differ: b" in report and "numpy 2.5.0 (goldens made with 2.4.6)" in report
    assert "mesa" not in report
    same = mismatch_report("x", expected, {"a": "0"}, expected["versions"])
    assert "a, b" in same and "the code changed these outputs" in same
