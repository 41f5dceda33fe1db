"""`farm reconstruct --method cloud|photos`: trees from point clouds and photo folders, one or a batch.

  farm reconstruct cloud.xyz --out tree.glb [--skeleton-ply s.ply] [--qsm-csv q.csv] [--branches-csv b.csv]
                   [--no-complete] [--up y]
  farm reconstruct photos/ --method photos --out tree.glb [--height 9 | --camera-height 1.5]
  farm reconstruct a.laz b.laz scans/ --out trees/          a batch: one tree each, summary.csv, contact_sheet.png

The method is inferred when omitted: cloud files -> cloud; a folder of images -> photos; a folder of cloud files or
of photo folders -> a batch of those. The measures (height, DBH by a circle fit at 1.3 m, crown projection, woody
volume by order) go in the GLB's extras and, one row a tree, in --qsm-csv (a batch: NAME.qsm.csv and summary.csv).
A batch runs one Ray task per tree; a tree that fails is reported in the summary and the others still finish (exit
status 2 if any failed). Photos: COLMAP's log goes to NAME.sfm.log beside each GLB (the summary line names it), the
registered cameras in the GLB's frame to NAME.cameras.json (a cameras.json the same photos can be run at again) and
each photo with the tree's outline over it to NAME.outlines.png; a single run shows a progress bar per stage.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import time
import traceback
from dataclasses import replace
from pathlib import Path

from reconstruct.methods import INPUT_KINDS, METHODS, RunOptions
from reconstruct.photo_folder import CAMERA_HEIGHT_M
from species.errors import TreefarmError, user_path

from farm.commands import CommandLineError
from farm.commands.ray_options import add_ray_options

SUMMARY_COLUMNS = ("input", "status", "output", "points", "height_m", "scan_height_m", "dbh_m", "dbh_method",
                   "crown_projection_area_m2", "crown_diameter_m", "total_volume_m3", "branches", "faces",
                   "outline_covers", "seconds", "message")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("point clouds and photos (--method cloud|photos)")
    group.add_argument("--up", default="z", help="the cloud's up axis: z, -z, y, -y, x, -x (default z)")
    group.add_argument("--frame", choices=("base", "scan"), default="base",
                       help="base: the trunk's base at the origin (default); scan: the scan's own coordinates")
    group.add_argument("--skeleton-ply", help="write the measured skeleton as PLY (vertices with radii, edges)")
    group.add_argument("--qsm-csv", help="write the tree's measures, one row: height, DBH (circle fit at 1.3 m), "
                                         "crown projection area and diameter, woody volume by order, lengths")
    group.add_argument("--branches-csv", help="write the branch table (id, parent, order, length, radius, volume)")
    group.add_argument("--complete", action=argparse.BooleanOptionalAction, default=True,
                       help="seed 003's editing: twigs, leaves and grafts into occlusion gaps (default on)")
    group.add_argument("--poses", choices=("auto", "known", "estimate"), default="auto",
                       help="photos: known (the folder's cameras.json), estimate (SfM's own, aligned onto "
                            "cameras.json when there is one) or auto (known when cameras.json lists every photo)")
    group.add_argument("--shape", choices=("sparse", "hull"), default="hull",
                       help="photos: the crown from the SfM points (sparse) or grown inside the visual hull of the "
                            "photos' tree masks (hull; --species picks the colonization preset)")
    group.add_argument("--masks", choices=("network", "classical"), default="network",
                       help="photos, hull: the tree masks by the tree mask network (default; --models picks a "
                            "registry's or a model folder's, else the shipped one) or classical (colour and sky)")
    group.add_argument("--camera-height", type=float, default=CAMERA_HEIGHT_M, metavar="M",
                       help="photos without cameras.json or --height: the cameras' height above the ground in "
                            "metres, which scales the tree (default 1.5, a phone held at chest height)")
    add_ray_options(group, workers_help="batch: Ray tasks at once (default: the CPUs)",
                    address_help="batch: a Ray cluster to join (default: a local Ray)")


def _is_cloud(path: Path) -> bool:
    from reconstruct.clouds import CLOUD_SUFFIXES

    return path.is_file() and path.suffix.lower() in CLOUD_SUFFIXES


def _is_photo_folder(path: Path) -> bool:
    from reconstruct.photo_folder import IMAGE_SUFFIXES

    return path.is_dir() and any(p.suffix.lower() in IMAGE_SUFFIXES for p in path.iterdir() if p.is_file())


def _scan_methods() -> dict[str, str]:
    """The registry's methods that read a cloud file or a photo folder -> that kind."""
    return {name: m.reads[0].kind for name, m in METHODS.items() if m.reads[0].kind in ("cloud", "photos")}


def cloud_inputs(args: argparse.Namespace) -> tuple[str, list[Path], bool] | None:
    """(method, inputs, batch) when the inputs are clouds or photo folders, else None (a drawing method).
    Without --method, a kind's method is the registry's first that reads it."""
    paths = [Path(p) for p in args.inputs]
    scans = _scan_methods()
    # the inputs of a method that reads flags only (two-view's --front/--side) make it that method
    flag_only = [item.name for m in METHODS.values() if all(i.flag for i in m.reads) for item in m.reads]
    if not paths or any(getattr(args, name) for name in flag_only):
        return None
    if args.method is not None and args.method not in scans:
        return None
    for path in paths:
        if not path.exists():
            if args.method in scans or path.suffix.lower() in _cloud_suffixes():
                raise CommandLineError(f"{path} does not exist: allowed a cloud file or a folder of photos")
            return None
    items: list[tuple[str, Path]] = []
    for path in paths:
        if _is_cloud(path):
            items.append(("cloud", path))
        elif _is_photo_folder(path):
            items.append(("photos", path))
        elif path.is_dir():
            inside = sorted(path.iterdir())
            items += [("cloud", p) for p in inside if _is_cloud(p)]
            items += [("photos", p) for p in inside if _is_photo_folder(p)]
            if not any(_is_cloud(p) or _is_photo_folder(p) for p in inside):
                raise CommandLineError(f"{path} holds no point cloud ({', '.join(_cloud_suffixes())}) and no photos: "
                                       "allowed a cloud file, a folder of photos, or a folder of those")
        elif args.method in scans:
            raise CommandLineError(f"{path} is not a point cloud: allowed {', '.join(_cloud_suffixes())} files or a "
                                   "folder of photos")
        else:
            return None
    kinds = {kind for kind, _ in items}
    if args.method is not None and kinds != {scans[args.method]}:
        kind, wrong = next((k, p) for k, p in items if k != scans[args.method])
        raise CommandLineError(f"--method {args.method} does not take {wrong}: it is {INPUT_KINDS[kind][0]}")
    if len(kinds) > 1:
        raise CommandLineError("the inputs mix point clouds and photo folders: allowed one kind a run (--method)")
    batch = len(items) > 1 or any(p.is_dir() and not _is_photo_folder(p) for p in paths) or Path(args.out).suffix == ""
    kind = kinds.pop()
    method = args.method or next(name for name, k in scans.items() if k == kind)
    return method, [p for _, p in items], batch


def _cloud_suffixes() -> tuple[str, ...]:
    from reconstruct.clouds import CLOUD_SUFFIXES

    return CLOUD_SUFFIXES


def _options(args: argparse.Namespace, batch: bool = False) -> RunOptions:
    """What each tree's reconstruction takes; a batch's SfM runs on one thread a Ray task."""
    return RunOptions(seed=args.seed, height=args.height, up=args.up, frame=args.frame, completion=args.complete,
                      poses=args.poses, threads=1 if batch else 0, shape=args.shape, species=args.species,
                      masks=args.masks, models=args.models, camera_height=args.camera_height)


def log_path(method: str, out: Path) -> Path | None:
    """Where a method that reads photos sends COLMAP's log: NAME.sfm.log beside the GLB; None for the others."""
    return out.with_suffix(".sfm.log") if METHODS[method].reads[0].kind == "photos" else None


def reconstruct_one(method: str, source: Path, out: Path, options: RunOptions, skeleton_ply: Path | None = None,
                    qsm_csv: Path | None = None, branches_csv: Path | None = None, report: Path | None = None) -> dict:
    """Reconstruct one tree and write its files (COLMAP's log at `log_path`); returns its summary row
    (TreefarmErrors propagate)."""
    started = time.perf_counter()
    entry = METHODS[method]
    log = log_path(method, out)
    if log is not None:
        with user_path(log, "write"):
            log.parent.mkdir(parents=True, exist_ok=True)
            log.write_bytes(b"")
    result = entry.run({entry.reads[0].name: source}, replace(options, name=out.stem, log=log))
    with user_path(out, "write"):
        result.write(out, skeleton_ply=skeleton_ply, qsm_csv=qsm_csv, branches_csv=branches_csv)
    covered = None
    if "cameras" in result.maps:
        import statistics

        from reconstruct.photo_outlines import write_outlines

        # the photos' own cameras, and the tree's outline drawn over each photo: where people check the result
        with user_path(out, "write"):
            shares = [c for c in write_outlines(result, source, out.with_suffix(".cameras.json"),
                                                out.with_suffix(".outlines.png")) if c is not None]
        covered = statistics.median(shares) if shares else None
    points = result.scan.cloud.points
    if report is not None:
        from reconstruct.report import cloud_drawing, write_report

        with user_path(report, "write"):
            write_report(report, [("cloud front", cloud_drawing(points, 0)), ("cloud side", cloud_drawing(points, 1))],
                         result.skeleton, result.mesh, title=f"{method}: {out.name}")
    measures = result.scan.measures
    return {"input": str(source), "status": "ok", "output": str(out), "points": len(points),
            "height_m": round(measures["height_m"], 3), "scan_height_m": _rounded(measures["scan_height_m"], 3),
            "dbh_m": _rounded(measures["dbh_m"], 4), "dbh_method": measures["dbh_method"],
            "crown_projection_area_m2": _rounded(measures["crown_projection_area_m2"], 2),
            "crown_diameter_m": _rounded(measures["crown_diameter_m"], 2),
            "total_volume_m3": round(measures["total_volume_m3"], 5), "branches": measures["branch_count"],
            "faces": result.mesh.n_faces, "seconds": round(time.perf_counter() - started, 3),
            "outline_covers": _rounded(covered, 3),
            "message": "; ".join(result.warnings), "_timings": result.timings, "_skeleton": result.skeleton,
            "_cloud": points}


def _rounded(value: float | None, digits: int) -> float | None:
    return None if value is None else round(value, digits)


def _outlines_said(row: dict, out: Path) -> str:
    """The summary line's words on the photos' outlines file, if one was written."""
    if row.get("outline_covers") is None:
        return ""
    return (f"; outlines {out.with_suffix('.outlines.png')}: a median {row['outline_covers']:.0%} of each photo's "
            f"tree mask inside")


def print_stages(timings: dict[str, float]) -> None:
    """--verbose: each stage's seconds, one a line, under the summary line's command."""
    for stage, seconds in timings.items():
        print(f"  {stage:<28} {seconds:7.2f} s")


def run_single(args: argparse.Namespace, method: str, source: Path) -> int:
    out = Path(args.out)
    if out.suffix.lower() != ".glb":
        raise CommandLineError(f"--out {args.out} must name a .glb file for --method {method} (the GLB carries the "
                               "frame and the measures in its extras), or a folder for a batch")
    if args.format not in (None, "glb"):
        raise CommandLineError(f"--format {args.format}: --method {method} writes glb only")
    log = log_path(method, out)
    bars = StageBars()
    try:
        row = reconstruct_one(method, source, out, replace(_options(args), progress=bars),
                              Path(args.skeleton_ply) if args.skeleton_ply else None,
                              Path(args.qsm_csv) if args.qsm_csv else None,
                              Path(args.branches_csv) if args.branches_csv else None,
                              Path(args.report) if args.report else None)
    except TreefarmError:
        if log is not None:  # a refused input writes nothing; the error line says what COLMAP could not do
            log.unlink(missing_ok=True)
        raise
    finally:
        bars.close()
    for warning in row["message"].split("; ") if row["message"] else []:
        print(f"warning: {warning}", file=sys.stderr)
    if args.verbose:
        print_stages(row["_timings"])
    dbh = "n/a" if row["dbh_m"] is None else f"{row['dbh_m']:.3f} m"
    print(f"{method}: {row['points']} points -> height {row['height_m']:.2f} m, DBH {dbh}, "
          f"volume {row['total_volume_m3']:.3f} m3, {row['branches']} branches -> {out} ({row['seconds']:.2f} s"
          f"{f'; log {log}' if log is not None else ''}{_outlines_said(row, out)})")
    return 0


class StageBars:
    """A `reconstruct.sfm.Progress` drawn as one progress bar per stage, on the terminal's stderr as it was when
    made: COLMAP's output is sent to its log while it runs, the bars are not. No bars where stderr is no terminal."""

    def __init__(self) -> None:
        self._terminal = os.fdopen(os.dup(2), "w")
        self._bar = None
        self._stage = None

    def __call__(self, stage: str, done: int, total: int) -> None:
        from tqdm import tqdm  # here: only a run with progress draws bars (start-up time)

        if stage != self._stage:
            self._close_bar()
            self._stage = stage
            self._bar = tqdm(total=total, desc=stage, unit="step" if stage == "tree" else "photo",
                             file=self._terminal, disable=None)
        self._bar.total = total
        self._bar.n = done
        self._bar.refresh()

    def _close_bar(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def close(self) -> None:
        self._close_bar()
        self._terminal.close()


def _batch_task(method: str, source: str, out: str, options: RunOptions, extras: bool) -> dict:
    out_path = Path(out)
    try:
        row = reconstruct_one(method, Path(source), out_path, options,
                              out_path.with_suffix(".skeleton.ply") if extras else None,
                              out_path.with_suffix(".qsm.csv") if extras else None,
                              out_path.with_suffix(".branches.csv") if extras else None)
        row["_skeleton"] = row["_skeleton"].to_arrays()
        row["_cloud"] = row["_cloud"][:: max(1, len(row["_cloud"]) // 20000)]
        return row
    except TreefarmError as error:
        return {"input": source, "status": "failed", "message": str(error)}
    except Exception:  # a bug: reported with its traceback, and the run exits 1
        return {"input": source, "status": "error", "message": traceback.format_exc()}


def _ray_rows(args: argparse.Namespace, tasks: list[tuple]) -> list[dict]:
    """Each task's `_batch_task` row, run as Ray tasks (on the cluster at --address, or a local Ray)."""
    import ray  # here: only a batch of several trees, or one sent to a cluster, starts Ray
    from tqdm import tqdm

    from farm.pipeline import ray_connection

    rows = []
    with ray_connection(args.address, args.workers, log_to_driver=False):
        task = ray.remote(num_cpus=1)(_batch_task)
        pending = [task.remote(*arguments) for arguments in tasks]
        with tqdm(total=len(pending), desc="reconstruct", unit="tree", disable=None) as bar:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                rows.append(ray.get(done[0]))
                bar.update(1)
    return rows


def run_batch(args: argparse.Namespace, method: str, sources: list[Path]) -> int:
    from renderers.contact_sheet import write_contact_sheet
    from reconstruct.report import cloud_drawing, skeleton_drawing
    from species.skeleton import Skeleton

    out_dir = Path(args.out)
    if out_dir.suffix:
        raise CommandLineError(f"--out {args.out}: a batch of {len(sources)} writes a folder (one GLB a tree); "
                               "allowed a folder name without a suffix")
    if args.skeleton_ply or args.qsm_csv or args.branches_csv or args.report:
        raise CommandLineError("--skeleton-ply, --qsm-csv, --branches-csv and --report name one file: a batch writes "
                               "NAME.skeleton.ply, NAME.qsm.csv and NAME.branches.csv beside each GLB, and "
                               "contact_sheet.png")
    stems = [s.stem if s.is_file() else s.name for s in sources]
    if len(set(stems)) < len(stems):
        twice = sorted({s for s in stems if stems.count(s) > 1})
        raise CommandLineError(f"inputs {twice} share a name: allowed inputs whose names differ (one GLB each)")
    with user_path(out_dir, "write"):
        out_dir.mkdir(parents=True, exist_ok=True)
    options = _options(args, batch=True)
    tasks = [(method, str(s), str(out_dir / f"{stem}.glb"), options, True) for s, stem in zip(sources, stems)]
    # One tree and no cluster named: it runs in this process, as Ray's start-up would take longer than the tree.
    rows = [_batch_task(*tasks[0])] if len(tasks) == 1 and args.address is None else _ray_rows(args, tasks)
    rows.sort(key=lambda r: r["input"])
    with user_path(out_dir / "summary.csv", "write"):
        with open(out_dir / "summary.csv", "w", newline="") as handle:
            writer = csv.DictWriter(handle, SUMMARY_COLUMNS, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(rows)
    sheet_rows = []
    for row in rows:
        if row["status"] == "ok":
            skeleton = Skeleton(**row["_skeleton"])
            sheet_rows.append((Path(row["input"]).name, [("cloud", cloud_drawing(row["_cloud"], 0)),
                                                         ("skeleton front", skeleton_drawing(skeleton, 0)),
                                                         ("skeleton side", skeleton_drawing(skeleton, 1))]))
    if sheet_rows:
        write_contact_sheet(out_dir / "contact_sheet.png", sheet_rows)
    print(f"{'input':<32} {'status':<7} {'height m':>8} {'DBH m':>7} {'volume m3':>10} {'branches':>8} {'s':>6}")
    for row in rows:
        if row["status"] == "ok":
            dbh = "-" if row["dbh_m"] is None else f"{row['dbh_m']:.3f}"
            print(f"{Path(row['input']).name:<32} ok      {row['height_m']:>8.2f} {dbh:>7} "
                  f"{row['total_volume_m3']:>10.4f} {row['branches']:>8} {row['seconds']:>6.2f}")
        else:
            print(f"{Path(row['input']).name:<32} {row['status']:<7} {row['message'].strip().splitlines()[-1]}")
    for row in rows:
        if row["status"] == "error":
            print(f"error in {row['input']}:\n{row['message']}", file=sys.stderr)
    ok = sum(r["status"] == "ok" for r in rows)
    logs = ", NAME.sfm.log (COLMAP's)" if log_path(method, out_dir / "NAME.glb") else ""
    print(f"{ok} of {len(rows)} trees -> {out_dir} (summary.csv, contact_sheet.png{logs})")
    if any(r["status"] == "error" for r in rows):
        return 1
    return 0 if ok == len(rows) else 2


def run(args: argparse.Namespace, method: str, sources: list[Path], batch: bool) -> int:
    if batch:
        return run_batch(args, method, sources)
    return run_single(args, method, sources[0])
