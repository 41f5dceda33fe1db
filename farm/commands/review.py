"""`farm review DIR [--port P] [--host H] [--token T]`: serve a dataset to reviewers (desktop browser or VR).

`farm review REPORT_DIR`: a `farm evaluate` report folder (it holds evaluation.json) opens as a table of its rows,
worst first, each with its panel (input | reconstruction | ground truth); nothing is written into the folder.

`farm review export DIR`: write the stored verdicts to DIR/reviews/part-00000.parquet (joinable by tree_id).
"""
from __future__ import annotations

import argparse
import sys

from farm.commands import check_flag_int

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("review", help="review a dataset in a browser or VR headset; `review export DIR`",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("target", metavar="DIR", help="dataset folder or evaluation report folder "
                                                      "(or `export` followed by a dataset folder)")
    parser.add_argument("export_dir", nargs="?", metavar="EXPORT_DIR", help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, default=8765, help="port to listen on (default 8765; 0 picks a free one)")
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    parser.add_argument("--token", help="access token (default: a new random one)")
    parser.add_argument("--db", help="reviews database (default: DIR/reviews.sqlite)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from farm.review.service import default_db_path
    from farm.review.store import ReviewError, ReviewStore

    check_flag_int("--port", args.port, 0, 65535)  # before a database is created
    if args.export_dir is not None:
        if args.target != "export":
            raise ReviewError(f"unexpected argument {args.export_dir!r}: use `farm review DIR` or "
                              f"`farm review export DIR`")
        from farm.dataset import read_manifest
        from farm.review.export import export_reviews

        read_manifest(args.export_dir)  # a dataset folder, before a database is created in it
        path, rows = export_reviews(args.export_dir, ReviewStore(args.db or default_db_path(args.export_dir)))
        print(f"{rows} verdicts -> {path}")
        return 0
    return serve(args)


def serve(args: argparse.Namespace) -> int:
    from farm.review.report import EvaluationReport, is_report
    from farm.review.server import ReviewServer, check_token, create_app, listen_socket, new_token
    from farm.review.service import ReviewService
    from farm.review.store import ReviewError

    report = is_report(args.target)
    if report and args.db is not None:
        raise ReviewError(f"--db is for datasets: {args.target} is an evaluation report, which stores no verdicts")
    token = check_token(args.token) if args.token else new_token()
    sock = listen_socket(args.host, args.port)  # a taken port is refused before the database is created
    try:
        service = EvaluationReport(args.target) if report else ReviewService(args.target, args.db, progress=True)
    except BaseException:
        sock.close()
        raise
    server = ReviewServer(create_app(service, token), args.host, sock=sock)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: listening on {args.host}: anyone who can reach it and has the token can "
              f"{'read the report' if report else 'review'}", file=sys.stderr)
    if report:
        rows = service.rows()
        failed = sum(row["status"] != "ok" for row in rows)
        print(f"reviewing evaluation report {args.target}: {len(rows)} rows ({failed} failed)")
    else:
        print(f"reviewing {service.index.name}: {len(service.index.trees)} trees, {len(service.qa)} with QA flags")
    print(f"open {server.url(token)}", flush=True)
    server.run()
    return 0
