"""docs/performance.md from the benchmarks' results files: one section per `benchmarks/results/NAME.json` (its
command, machine, commit and tables), the headline set first, between two marker lines; the rest of the page (the
figures of longer runs, written by hand) is kept as it is.

Run: python -m benchmarks.performance_doc [--results DIR] [--doc FILE]   (`make bench` runs it last)
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Sequence

from benchmarks.harness import RESULTS, ROOT, read_results
from benchmarks.headline import HEADLINE

DOC = ROOT / "docs" / "performance.md"
BEGIN = "<!-- benchmarks/performance_doc.py writes from here to the end marker: edit the results, not this -->"
END = "<!-- end of the generated part -->"
INTRO = ("Each section below was written by `python -m benchmarks.performance_doc` from "
         "`benchmarks/results/NAME.json`, which the benchmark named in it wrote; `make bench` runs the headline set "
         "with settings short enough for a few minutes on 2 cores and then this generator. Wall times on a shared "
         "machine are noisy: the load average when the run started is given with the machine.")
TITLE = "# Performance"


def markdown_table(columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    def text(value: Any) -> str:
        return "" if value is None else str(value).replace("|", "\\|")

    lines = ["| " + " | ".join(map(text, columns)) + " |", "|" + "---|" * len(columns)]
    return lines + ["| " + " | ".join(map(text, row)) + " |" for row in rows]


def machine_line(machine: dict) -> str:
    gpu = "no GPU" if machine.get("gpu") in (None, "none") else machine["gpu"]
    cores = f"{machine['cores']} cores"
    if machine.get("cores_usable") not in (None, machine["cores"]):
        cores += f" ({machine['cores_usable']} usable)"
    return (f"{machine['cpu']}, {cores}, {machine.get('memory_gib')} GiB, {gpu}; "
            f"load average {machine.get('load_average')} at the start")


def section(record: dict) -> list[str]:
    """One results file as markdown: title, command, machine, versions, commit, figures, tables, notes."""
    git = record["git"]
    commit = (git["commit"] or "unknown")[:10] + (" with local changes" if git.get("modified") else "")
    versions = ", ".join(f"{name} {version}" for name, version in record["versions"].items())
    lines = [f"## {record['title']}", "", f"`{record['command']}`", "",
             f"- machine: {machine_line(record['machine'])}", f"- versions: {versions}",
             f"- commit {commit}, {record['date']}", ""]
    if record["figures"]:
        lines += markdown_table(["figure", "value", "reference"],
                                [[name, f"{f['value']} {f['unit']}", f["reference"]]
                                 for name, f in record["figures"].items()]) + [""]
    for table in record["tables"]:
        lines += [f"### {table['title']}", ""] + markdown_table(table["columns"], table["rows"]) + [""]
        lines += [f"- {note}" for note in table["notes"]] + ([""] if table["notes"] else [])
    lines += [f"{note}  " for note in record["notes"]] + ([""] if record["notes"] else [])
    return lines


def generated_part(records: list[dict]) -> str:
    lines = [BEGIN, "", INTRO, ""]
    for record in records:
        lines += section(record)
    return "\n".join(lines + [END])


def ordered(results: Path, first: Sequence[str]) -> list[dict]:
    """The results files of `results`, those named in `first` first in that order, then the rest by name."""
    records = {path.stem: read_results(path) for path in sorted(results.glob("*.json"))}
    names = [n for n in first if n in records] + sorted(set(records) - set(first))
    return [records[name] for name in names]


def render(doc_text: str | None, records: list[dict]) -> str:
    """The page with its generated part replaced (or a new page: title, then the generated part)."""
    part = generated_part(records)
    if doc_text is None or BEGIN not in doc_text:
        return f"{TITLE}\n\n{part}\n" + ("" if doc_text is None else "\n" + doc_text)
    before, rest = doc_text.split(BEGIN, 1)
    if END not in rest:
        raise ValueError(f"the page has the begin marker but not the end marker: {END}")
    return before + part + rest.split(END, 1)[1]


def write_doc(results: Path = RESULTS, doc: Path = DOC, first: Sequence[str] = ()) -> Path:
    doc.write_text(render(doc.read_text() if doc.is_file() else None, ordered(results, first)))
    return doc


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--doc", type=Path, default=DOC)
    args = parser.parse_args(argv)
    print(f"wrote {write_doc(args.results, args.doc, [case.name for case in HEADLINE])}")


if __name__ == "__main__":
    main()
