"""The review client: a token-guarded ASGI server over a dataset's Parquet shards, verdicts in SQLite, QA flags."""
