"""QSM measures on real scans beside what others measured on the same trees (issue 50): height, DBH (a circle fit
at 1.3 m, or the skeleton's radius where the scan holds too little stem), crown projection area and diameter, and
woody volume, from `farm reconstruct`'s cloud method (`reconstruct.from_cloud`, measures by `reconstruct.qsm`).

References, from ../shared/data/pointclouds/README.md and its files: the two Amsterdam street trees'
`street_trees_ahn/results.csv` (another pipeline's estimates, not field measurements: height from its ground point,
DBH from the dense stem scans, crown diameter as the smallest circle enclosing the crown's projection), the
conifers' heights (pine 20.2 m, spruce 16.9 m) and the tall tree's 37.8 m. The street trees' airborne scans hold
little stem, so their DBH is read from the dense mobile-lidar stem scans (`sonarski/`), as a user would; the
airborne scan's own DBH is shown beside. Heights are given above the tree's base (its lowest scanned stem point)
and, where the reference gives its ground point, above that ground as the reference measures them.

Run: python -m benchmarks.bench_qsm [--data ../shared/data/pointclouds]
"""
from __future__ import annotations

from benchmarks.harness import ROOT, Benchmark, arguments, pin_threads

pin_threads()

import csv  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from reconstruct.from_cloud import from_cloud  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "pointclouds"
STREET_TREES = ("121913_487434", "121922_487459")
# (label, path under DATA, reference height m or None, where the reference comes from)
SCANS = [
    ("tree1 (TLS)", "tree1.xyz", None, "AdTree's sample: no reference"),
    ("pine (TLS, stem clip)", "conifer_stems/pine.laz", 20.2, "README"),
    ("spruce (TLS, stem clip)", "conifer_stems/spruce.laz", 16.9, "README"),
    ("tall_wood (TLS, wood)", "tall_wood/test_data_wood.txt", 37.8, "README"),
]
COLUMNS = ["scan", "points", "height m", "ref. height m", "DBH m (method)", "ref. DBH m", "crown area m2",
           "crown diam. m", "ref. crown diam. m", "volume m3", "s"]


def reference_rows(data: Path) -> dict[tuple[str, str], dict]:
    """results.csv's rows by (treecode, source), their numbers as floats (None where empty)."""
    rows = {}
    with open(data / "street_trees_ahn" / "results.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            numbers = {k: float(v) if v not in ("", None) and k not in ("source", "treecode", "stem_basepoint",
                                                                         "crown_shape") else v
                       for k, v in row.items()}
            numbers["ground_z"] = float(row["stem_basepoint"].strip("[]").split()[2])
            rows[row["treecode"], row["source"]] = numbers
    return rows


def measure(path: Path) -> tuple[dict, float, float, int]:
    """(measures, the top's z in the scan's frame, seconds, points) of one scan (no completion: the measures are
    the measured skeleton's and the points')."""
    started = time.perf_counter()
    result = from_cloud(path, completion=False)
    seconds = time.perf_counter() - started
    scan = result.scan
    top_z = float(scan.cloud.points[:, 2].max() + scan.cloud.offset[2])
    return scan.measures, top_z, seconds, len(scan.cloud.points)


def dbh_cell(measures: dict) -> str:
    if measures["dbh_m"] is None:
        return "n/a"
    method = "circle" if measures["dbh_method"] == "circle fit" else "skeleton"
    arc = f", {measures['dbh_arc_deg']:.0f} deg" if measures["dbh_arc_deg"] is not None else ""
    return f"{measures['dbh_m']:.3f} ({method}{arc})"


def row(label: str, measures: dict, seconds: float, points: int, height: str, ref_height, ref_dbh, ref_crown):
    def number(value, digits=2):
        return "-" if value is None else f"{value:.{digits}f}"

    return [label, points, height, number(ref_height), dbh_cell(measures), number(ref_dbh, 3),
            number(measures["crown_projection_area_m2"], 1), number(measures["crown_diameter_m"]),
            number(ref_crown), f"{measures['total_volume_m3']:.3f}", f"{seconds:.1f}"]


def main() -> None:
    parser = arguments(__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DATA, help="the shared point clouds (default: %(default)s)")
    args = parser.parse_args()
    bench = Benchmark("qsm", "QSM measures on real scans beside the references their READMEs give", args)
    if not args.data.is_dir():
        bench.note(f"{args.data} is missing: nothing to measure")
        bench.write()
        return
    rows = []
    for label, name, ref_height, _ in SCANS:
        if (args.data / name).is_file():
            measures, _, seconds, points = measure(args.data / name)
            rows.append(row(label, measures, seconds, points, f"{measures['scan_height_m']:.2f}", ref_height,
                            None, None))
    references = reference_rows(args.data)
    street = args.data / "street_trees_ahn"
    for code in STREET_TREES:
        airborne = street / "ahn" / f"filtered_tree_{code}.las"
        stem = street / "sonarski" / f"stem_{code}.las"
        if not airborne.is_file():
            continue
        ahn = references[code, "ahn"]
        measures, top_z, seconds, points = measure(airborne)
        height = f"{measures['scan_height_m']:.2f} / {top_z - ahn['ground_z']:.2f}"
        rows.append(row(f"{code} AHN (airborne)", measures, seconds, points, height, ahn["tree_height"], None,
                        ahn["crown_diameter"]))
        if stem.is_file():
            dbh_refs = [references[code, s]["DBH"] for s in ("sonarski", "cyclo") if references[code, s]["DBH"]]
            measures, _, seconds, points = measure(stem)
            rows.append(row(f"{code} sonarski stem (MLS)", measures, seconds, points,
                            f"{measures['scan_height_m']:.2f}", None, dbh_refs[0] if dbh_refs else None, None))
    bench.table("QSM measures against the references (heights: above the scan's base; for AHN, base / above "
                "results.csv's ground point)", COLUMNS, rows,
                ["ref.: street trees from street_trees_ahn/results.csv (the ahn row for height and crown, the "
                 "sonarski row for DBH, else cyclo's); conifers and tall_wood from the README",
                 "crown area: convex hull of the ground projection; crown diam.: its smallest enclosing circle, as "
                 "results.csv's crown_diameter is computed"])
    bench.write()


if __name__ == "__main__":
    main()
