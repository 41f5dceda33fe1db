"""The review service behind the HTTP layer: dataset index + verdict store + QA flags, and tree queries.

`ReviewService(dataset, db)` opens the dataset, computes QA flags for batches not yet cached in the SQLite file,
and answers the server's questions (filtered, paged tree lists; one tree's details; verdicts) as plain dicts.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from farm.dataset.storage import Location

from .index import DatasetIndex, NotFound
from .qa import FLAGS
from .store import DB_NAME, VERDICTS, ReviewError, ReviewStore, check_verdict

__all__ = ["ReviewService", "TreeQuery", "MAX_PER_PAGE", "default_db_path"]

MAX_PER_PAGE = 200
# Filter values besides the verdict and flag names themselves.
NO_VERDICT, ANY_FLAG, NO_FLAG = "none", "any", "none"


def default_db_path(dataset: str) -> Path:
    """`reviews.sqlite` in the dataset folder (a local folder: SQLite needs a local file)."""
    location = Location.resolve(dataset)
    if not location.is_local:
        raise ReviewError(f"{dataset} is not a local folder: pass --db PATH for the reviews database")
    return Path(location.root) / DB_NAME


class TreeQuery:
    """Validated filters and paging of a tree list request (every value a string, as in a query string)."""

    FIELDS = ("batch", "species", "generator", "verdict", "flag", "reviewer", "page", "per_page")

    def __init__(self, params: dict[str, str]):
        unknown = set(params) - set(self.FIELDS) - {"token"}
        if unknown:
            raise ReviewError(f"unknown tree filter(s) {', '.join(sorted(unknown))}; allowed {', '.join(self.FIELDS)}")
        self.batch = params.get("batch") or None
        self.species = [s for s in (params.get("species") or "").split(",") if s]
        self.generator = params.get("generator") or None
        self.verdict = params.get("verdict") or None
        if self.verdict is not None and self.verdict not in (*VERDICTS, NO_VERDICT):
            raise ReviewError(f"verdict filter {self.verdict!r} is invalid: "
                              f"allowed {', '.join(VERDICTS)}, {NO_VERDICT}")
        self.flag = params.get("flag") or None
        if self.flag is not None and self.flag not in (*FLAGS, ANY_FLAG, NO_FLAG):
            raise ReviewError(f"flag filter {self.flag!r} is invalid: "
                              f"allowed {', '.join(FLAGS)}, {ANY_FLAG}, {NO_FLAG}")
        self.reviewer = params.get("reviewer") or None
        self.page = _int_field("page", params.get("page", "1"), 1, 10**9)
        self.per_page = _int_field("per_page", params.get("per_page", "24"), 1, MAX_PER_PAGE)


def _int_field(name: str, value: str, low: int, high: int) -> int:
    try:
        number = int(value)
    except (TypeError, ValueError):
        number = None
    if number is None or not low <= number <= high:
        raise ReviewError(f"{name} = {value!r} is invalid: allowed an integer in [{low}, {high}]")
    return number


def _plain(value):
    """JSON-safe scalar: numpy numbers as Python numbers, NaN (pandas' missing value) as None."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and math.isnan(value):
        return None
    return value


class ReviewService:
    """One dataset under review. Thread-safe: the index is read-only after start, the store opens per call."""

    def __init__(self, dataset: str, db: str | Path | None = None, progress: bool = False):
        self.index = DatasetIndex(dataset)
        self.store = ReviewStore(db if db is not None else default_db_path(dataset))
        self.qa = self._load_qa(progress)

    def _load_qa(self, progress: bool) -> dict[str, dict[str, float]]:
        """Flags of every batch: cached ones from the store, the others computed now and cached."""
        from tqdm import tqdm

        todo = [b for b in self.index.batches if not self.store.qa_batch_done(b["qa_key"])]
        for batch in tqdm(todo, desc="QA flags", unit="batch", disable=not progress or not todo):
            self.store.put_qa_batch(batch["qa_key"], batch["id"], self.index.compute_qa(batch).rows())
        return self.store.qa_flags([b["qa_key"] for b in self.index.batches])

    # ------------------------------------------------------------------ reads
    def summary(self) -> dict:
        """The dataset, its batches (one per shard) with flag and verdict counts, species and generators."""
        trees = self.index.trees
        verdicts = self.store.verdict_summary()
        batches = []
        for batch in self.index.batches:
            ids = trees.index[trees["batch"] == batch["id"]]
            batches.append({"id": batch["id"], "shard": batch["shard"], "trees": batch["trees"],
                            "flagged": sum(1 for t in ids if t in self.qa),
                            "reviewed": sum(1 for t in ids if t in verdicts)})
        return {"dataset": self.index.name, "trees": len(trees), "outputs": self.index.outputs,
                "sketch_output": self.index.sketch_output, "batches": batches,
                "species": sorted(trees["species"].unique().tolist()),
                "generators": sorted(g for g in trees["generator"].dropna().unique().tolist()),
                "flags": FLAGS, "verdicts": list(VERDICTS)}

    def list_trees(self, query: TreeQuery) -> dict:
        """One page of trees matching the query, with flags, verdict counts and the reviewer's own verdict."""
        trees = self.index.trees
        keep = np.ones(len(trees), bool)
        if query.batch is not None:
            self.index.batch(query.batch)
            keep &= (trees["batch"] == query.batch).to_numpy()
        if query.species:
            keep &= trees["species"].isin(query.species).to_numpy()
        if query.generator is not None:
            keep &= (trees["generator"] == query.generator).to_numpy()
        if query.flag is not None:
            if query.flag in (ANY_FLAG, NO_FLAG):
                flagged = trees.index.isin(list(self.qa))
                keep &= flagged if query.flag == ANY_FLAG else ~flagged
            else:
                keep &= trees.index.isin([t for t, flags in self.qa.items() if query.flag in flags])
        summary = self.store.verdict_summary()
        mine = self._reviewer_verdicts(query.reviewer) if query.reviewer else {}
        if query.verdict is not None:
            given = {t: {v} for t, v in mine.items()} if query.reviewer else summary
            if query.verdict == NO_VERDICT:
                keep &= ~trees.index.isin(list(given))
            else:
                keep &= trees.index.isin([t for t, verdicts in given.items() if query.verdict in verdicts])
        matching = trees[keep].sort_values("index")
        start = (query.page - 1) * query.per_page
        page = matching.iloc[start:start + query.per_page]
        return {"total": int(len(matching)), "page": query.page, "per_page": query.per_page,
                "pages": max(1, -(-len(matching) // query.per_page)),
                "trees": [self._tree_entry(row, summary, mine) for row in page.to_dict("records")]}

    def _reviewer_verdicts(self, reviewer: str) -> dict[str, str]:
        return {v["tree_id"]: v["verdict"] for v in self.store.verdicts() if v["reviewer"] == reviewer}

    def _tree_entry(self, row: dict, summary: dict, mine: dict) -> dict:
        entry = {key: _plain(value) for key, value in row.items()}
        tree_id = entry["tree_id"]
        entry["seed"] = None if entry.get("seed") is None else str(entry["seed"])  # 63 bits: beyond a JS number
        entry["triangles"] = (None if entry["bark_triangles"] is None
                              else int(entry["bark_triangles"]) + int(entry["leaf_triangles"] or 0))
        entry["flags"] = self.qa.get(tree_id, {})
        entry["verdicts"] = summary.get(tree_id, {})
        entry["mine"] = mine.get(tree_id)
        return entry

    def tree(self, tree_id: str, reviewer: str | None = None) -> dict:
        """One tree's list entry plus its parameters, views and every reviewer's verdict."""
        self.index.ref(tree_id)
        row = self.index.trees.loc[tree_id].to_dict()
        mine = self._reviewer_verdicts(reviewer) if reviewer else {}
        entry = self._tree_entry(row, self.store.verdict_summary(), mine)
        entry["params"] = self.index.params(tree_id)
        entry["views"] = self.index.views(tree_id)
        entry["reviews"] = self.store.verdicts(tree_id)
        return entry

    def neighbours(self, tree_id: str) -> dict:
        """The trees before and after this one in index order (for 'next' without a list at hand)."""
        ids = self.index.trees.sort_values("index").index.tolist()
        if tree_id not in self.index.trees.index:
            raise NotFound(f"tree {tree_id!r} is not in dataset {self.index.name!r}")
        at = ids.index(tree_id)
        return {"previous": ids[at - 1] if at > 0 else None, "next": ids[at + 1] if at + 1 < len(ids) else None}

    # ------------------------------------------------------------------ writes
    def post_verdict(self, body: object) -> dict:
        """Validate and store one verdict (replacing the reviewer's earlier one on that tree)."""
        checked = check_verdict(body)
        self.index.ref(checked["tree_id"])
        return self.store.put_verdict(**checked)

