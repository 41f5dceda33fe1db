"""The benchmark harness: a case timed over repeats, a results file with the machine, versions and commit, and
docs/performance.md rendered from results files without touching the page's hand-written part."""
from __future__ import annotations

import argparse
import json
import re

import pytest

from benchmarks import harness, performance_doc
from benchmarks.headline import HEADLINE
from farm.dataset import DatasetError


def test_a_case_timed_over_repeats_keeps_every_repeat_and_the_last_result():
    calls = []
    timing = harness.time_case(lambda: calls.append(len(calls)) or len(calls), repeats=5, warmup=2)
    assert len(calls) == 7 and timing.result == 7
    assert len(timing.wall) == len(timing.cpu) == 5
    assert min(timing.wall) <= timing.median <= max(timing.wall) and timing.spread >= 0
    per_item = timing.scaled(4)
    assert per_item.median == pytest.approx(timing.median / 4) and per_item.result == timing.result


def test_zero_repeats_are_refused():
    with pytest.raises(ValueError, match="repeats = 0"):
        harness.time_case(lambda: None, repeats=0)


@pytest.fixture
def written(tmp_path, capsys):
    bench = harness.Benchmark("toy", "A toy benchmark", argparse.Namespace(repeats=3, no_results=False))
    timing = harness.time_case(lambda: sum(range(1000)), repeats=3)
    bench.table("sums", ["case", "ms", "reference"], [("sum of 1000", timing, "< 1 ms")], notes=["a reference"])
    bench.figure("sum speed", 1 / timing.median, "sums/s", "none")
    bench.note("a note")
    path = bench.write(tmp_path)
    return path, capsys.readouterr().out


def test_results_file_holds_the_machine_versions_commit_and_tables(written):
    path, printed = written
    record = harness.read_results(path)
    assert path.name == "toy.json" and record["name"] == "toy"
    assert record["machine"]["cores"] >= 1 and record["machine"]["cpu"] and record["machine"]["memory_gib"] > 0
    assert {"python", "numpy"} <= set(record["versions"])
    assert re.fullmatch(r"[0-9a-f]{40}", record["git"]["commit"])
    assert record["options"] == {"repeats": 3, "no_results": False}
    [table] = record["tables"]
    assert table["columns"] == ["case", "ms", "reference"] and table["rows"][0][0] == "sum of 1000"
    assert isinstance(table["rows"][0][1], float)  # a timing is stored as its median in ms
    assert record["figures"]["sum speed"]["unit"] == "sums/s" and record["notes"] == ["a note"]
    assert "sums" in printed and "sum of 1000" in printed and "a reference" in printed


def test_no_results_option_writes_nothing(tmp_path):
    bench = harness.Benchmark("toy", "A toy benchmark", argparse.Namespace(no_results=True))
    assert bench.write(tmp_path) is None and not list(tmp_path.iterdir())


def test_a_file_of_another_format_is_refused(tmp_path):
    path = tmp_path / "other.json"
    path.write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(DatasetError, match="format 'something-else', allowed 'treefarm-benchmark-results'"):
        harness.read_results(path)


def test_doc_renders_each_result_with_its_command_machine_and_tables(written):
    path, _ = written
    page = performance_doc.render(None, performance_doc.ordered(path.parent, ["toy"]))
    assert page.startswith("# Performance\n") and performance_doc.BEGIN in page and performance_doc.END in page
    assert "## A toy benchmark" in page and "`python" in page and "- machine: " in page
    assert "| case | ms | reference |" in page and "| sum of 1000 |" in page and "- a reference" in page


def test_doc_regeneration_keeps_the_hand_written_part(written):
    path, _ = written
    records = performance_doc.ordered(path.parent, [])
    page = performance_doc.render(None, records)
    edited = page.replace("# Performance\n", "# Performance\n\nHand-written intro.\n") + "\n## Longer runs\n\nKept.\n"
    again = performance_doc.render(edited, records)
    assert again == edited
    assert performance_doc.render(edited.replace("| sum of 1000 |", "| stale |"), records) == edited


def test_every_headline_benchmark_is_a_module_here():
    for run in HEADLINE:
        assert (harness.ROOT / "benchmarks" / f"{run.module}.py").is_file(), run.module
    assert len({run.name for run in HEADLINE}) == len(HEADLINE)
