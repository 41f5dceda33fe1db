"""Golden outputs: every preset's tree, the TreeSketchNet dictionaries, a small job's part files and a one-asset
library are byte-identical to the digests in `tests/golden/` (rewritten by `make golden` when outputs change on
purpose), on this platform's entry (`goldens.platform()`: rasterised bytes differ between CPUs). A mismatch names
what changed and any dependency whose version differs from the goldens'."""
from __future__ import annotations

import pytest

from golden import goldens


def mismatch_report(name: str, expected: dict, found: dict, found_versions: dict) -> str:
    """expected: {"digests": ..., "versions": ...}."""
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


@pytest.fixture(scope="module")
def here():
    return goldens.platform()


@pytest.mark.slow
@pytest.mark.parametrize("name", list(goldens.GOLDENS))
def test_outputs_match_their_golden_digests(name, tmp_path, found_versions, here):
    digests, made_with, unchecked = goldens.expected_digests(goldens.load(name), here)
    found = {k: v for k, v in goldens.compute(name, tmp_path).items() if k not in unchecked}
    assert found == digests, mismatch_report(name, {"digests": digests, "versions": made_with}, found,
                                             found_versions)
    if unchecked:
        pytest.skip(f"golden {name!r}: this platform ({here}) has no entry; {len(digests)} outputs match, and "
                    f"{', '.join(unchecked)} (bytes that differ between recorded platforms) cannot be checked here: "
                    "`make golden` on a commit known to be right records this platform")


def test_an_unrecorded_platform_is_checked_on_the_outputs_every_platform_agrees_on():
    entries = {"p1": {"versions": {"numpy": "1"}, "digests": {"tree": "a", "views": "b"}},
               "p2": {"versions": {"numpy": "1"}, "digests": {"tree": "a", "views": "c"}}}
    assert goldens.expected_digests(entries, "p2") == ({"tree": "a", "views": "c"}, {"numpy": "1"}, [])
    assert goldens.expected_digests(entries, "p3") == ({"tree": "a"}, {"numpy": "1"}, ["views"])


def test_a_mismatch_report_names_the_changed_outputs_and_moved_versions():
    expected = {"digests": {"a": "1", "b": "2"}, "versions": {"numpy": "2.4.6", "mesa": "22"}}
    report = mismatch_report("x", expected, {"a": "1", "b": "3"}, {"numpy": "2.5.0", "mesa": "22"})
    assert "1 of 2 outputs differ: b" in report and "numpy 2.5.0 (goldens made with 2.4.6)" in report
    assert "mesa" not in report
    same = mismatch_report("x", expected, {"a": "0"}, expected["versions"])
    assert "a, b" in same and "the code changed these outputs" in same
