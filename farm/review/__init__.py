"""The review client: a token-guarded ASGI server over a dataset's Parquet shards and its three.js/WebXR page.

Verdicts live in SQLite beside the dataset (`reviews.sqlite`), QA flags are cached there per batch, and
`export_reviews` writes them to `reviews/part-00000.parquet`. CLI: `farm review DIR`, `farm review export DIR`.
"""
from .export import REVIEWS_PART, export_reviews
from .qa import FLAGS
from .server import ReviewServer, create_app, new_token
from .service import ReviewService
from .store import VERDICTS, ReviewError, ReviewStore

__all__ = ["ReviewService", "ReviewStore", "ReviewServer", "ReviewError", "create_app", "new_token", "export_reviews",
           "REVIEWS_PART", "FLAGS", "VERDICTS"]
