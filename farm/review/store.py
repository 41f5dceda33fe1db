"""Reviewers' verdicts and cached QA flags in one SQLite file beside the dataset (WAL, one connection per call).

A verdict is (tree_id, reviewer, verdict, note, time); posting again for the same reviewer and tree replaces it,
so a verdict is stored once however often it is sent. QA flags are cached per batch under the part's checksum.
"""
from __future__ import annotations

import sqlite3
import time
from contextlib import closing, contextmanager
from pathlib import Path

from species.errors import TreefarmError

__all__ = ["ReviewStore", "ReviewError", "VERDICTS", "DB_NAME", "check_verdict"]

DB_NAME = "reviews.sqlite"
VERDICTS = ("approve", "reject", "flag")
MAX_REVIEWER = 64
MAX_NOTE = 2000
# Seconds a writer waits for another's lock before giving up (many reviewers, one file).
BUSY_TIMEOUT_S = 30.0

_SCHEMA = """
CREATE TABLE IF NOT EXISTS verdicts (
    tree_id TEXT NOT NULL, reviewer TEXT NOT NULL, verdict TEXT NOT NULL, note TEXT NOT NULL,
    time_ms INTEGER NOT NULL, PRIMARY KEY (tree_id, reviewer));
CREATE TABLE IF NOT EXISTS qa_batches (batch_key TEXT PRIMARY KEY, batch TEXT NOT NULL, computed_ms INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS qa_flags (
    batch_key TEXT NOT NULL, tree_id TEXT NOT NULL, flag TEXT NOT NULL, value REAL,
    PRIMARY KEY (batch_key, tree_id, flag));
"""


class ReviewError(TreefarmError):
    """A verdict or request with a missing or invalid field; the message names the field and what is allowed."""


def check_verdict(body: object) -> dict:
    """A posted verdict mapping validated to {tree_id, reviewer, verdict, note}; ReviewError names a bad field."""
    if not isinstance(body, dict):
        raise ReviewError(f"verdict body is {type(body).__name__}; allowed a JSON object with tree_id, reviewer, "
                          f"verdict and note")
    unknown = set(body) - {"tree_id", "reviewer", "verdict", "note"}
    if unknown:
        raise ReviewError(f"unknown verdict field(s) {', '.join(sorted(unknown))}; allowed tree_id, reviewer, "
                          f"verdict, note")
    out = {}
    for key, limit in (("tree_id", 256), ("reviewer", MAX_REVIEWER)):
        value = body.get(key)
        if not isinstance(value, str) or not value.strip() or len(value) > limit:
            raise ReviewError(f"{key} = {value!r} is invalid: allowed a non-empty string of at most {limit} characters")
        out[key] = value.strip()
    verdict = body.get("verdict")
    if verdict not in VERDICTS:
        raise ReviewError(f"verdict = {verdict!r} is invalid: allowed {', '.join(VERDICTS)}")
    note = body.get("note", "")
    if note is None:
        note = ""
    if not isinstance(note, str) or len(note) > MAX_NOTE:
        raise ReviewError(f"note = {str(note)[:40]!r} is invalid: allowed a string of at most {MAX_NOTE} characters")
    if verdict == "flag" and not note.strip():
        raise ReviewError("note is empty: a 'flag' verdict needs a note saying what is wrong")
    out["verdict"], out["note"] = verdict, note.strip()
    return out


class ReviewStore:
    """The SQLite file of one dataset's reviews. Safe to share between threads and processes."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise ReviewError(f"review database folder {self.path.parent} does not exist")
        try:
            with self._connect() as connection:
                connection.execute("PRAGMA journal_mode=WAL")
                connection.executescript(_SCHEMA)
        except sqlite3.OperationalError as exc:  # a read-only dataset folder, or a file that is not SQLite
            raise ReviewError(f"cannot open the review database {self.path} ({exc}): pass --db PATH to keep the "
                              f"reviews in a writable place") from None

    @contextmanager
    def _connect(self):
        # A connection per call: sqlite3 connections are not shared between the server's threads.
        with closing(sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, isolation_level=None)) as connection:
            connection.execute("PRAGMA synchronous=NORMAL")
            yield connection

    # ------------------------------------------------------------------ verdicts
    def put_verdict(self, tree_id: str, reviewer: str, verdict: str, note: str = "",
                    time_ms: int | None = None) -> dict:
        """Store (or replace) `reviewer`'s verdict on `tree_id`; returns the stored row."""
        checked = check_verdict({"tree_id": tree_id, "reviewer": reviewer, "verdict": verdict, "note": note})
        checked["time_ms"] = int(time.time() * 1000) if time_ms is None else int(time_ms)
        with self._connect() as connection:
            connection.execute(
                "INSERT INTO verdicts (tree_id, reviewer, verdict, note, time_ms) "
                "VALUES (:tree_id, :reviewer, :verdict, :note, :time_ms) "
                "ON CONFLICT (tree_id, reviewer) DO UPDATE SET verdict = excluded.verdict, note = excluded.note, "
                "time_ms = excluded.time_ms", checked)
        return checked

    def verdicts(self, tree_id: str | None = None) -> list[dict]:
        """Every stored verdict (of one tree if given), ordered by tree id then reviewer."""
        query = "SELECT tree_id, reviewer, verdict, note, time_ms FROM verdicts"
        args: tuple = ()
        if tree_id is not None:
            query, args = query + " WHERE tree_id = ?", (tree_id,)
        with self._connect() as connection:
            rows = connection.execute(query + " ORDER BY tree_id, reviewer", args).fetchall()
        keys = ("tree_id", "reviewer", "verdict", "note", "time_ms")
        return [dict(zip(keys, row)) for row in rows]

    def verdict_summary(self) -> dict[str, dict[str, int]]:
        """tree_id -> {verdict: number of reviewers who gave it}."""
        with self._connect() as connection:
            rows = connection.execute("SELECT tree_id, verdict, count(*) FROM verdicts GROUP BY tree_id, verdict")
            summary: dict[str, dict[str, int]] = {}
            for tree_id, verdict, count in rows:
                summary.setdefault(tree_id, {})[verdict] = count
        return summary

    # ------------------------------------------------------------------ QA flag cache
    def qa_batch_done(self, batch_key: str) -> bool:
        with self._connect() as connection:
            row = connection.execute("SELECT 1 FROM qa_batches WHERE batch_key = ?", (batch_key,)).fetchone()
        return row is not None

    def put_qa_batch(self, batch_key: str, batch: str, rows: list[tuple[str, str, float]]) -> None:
        """Cache one batch's raised flags (tree_id, flag, value) under its key, in one transaction."""
        with self._connect() as connection:
            connection.execute("BEGIN IMMEDIATE")
            connection.execute("DELETE FROM qa_flags WHERE batch_key = ?", (batch_key,))
            connection.executemany("INSERT INTO qa_flags (batch_key, tree_id, flag, value) VALUES (?, ?, ?, ?)",
                                   [(batch_key, *row) for row in rows])
            connection.execute("INSERT OR REPLACE INTO qa_batches (batch_key, batch, computed_ms) VALUES (?, ?, ?)",
                               (batch_key, batch, int(time.time() * 1000)))
            connection.execute("COMMIT")

    def qa_flags(self, batch_keys: list[str]) -> dict[str, dict[str, float]]:
        """tree_id -> {flag: value} over the given batches."""
        flags: dict[str, dict[str, float]] = {}
        with self._connect() as connection:
            for key in batch_keys:
                for tree_id, flag, value in connection.execute(
                        "SELECT tree_id, flag, value FROM qa_flags WHERE batch_key = ?", (key,)):
                    flags.setdefault(tree_id, {})[flag] = value
        return flags
