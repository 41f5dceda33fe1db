"""JSON files that name their format: read, parsed and checked in one place (a dataset's manifest, a training split,
an evaluation report's job), so each refuses a missing file, text that is not JSON and another format alike.

Such a file holds a JSON object whose "format" key names what wrote it ("treefarm-dataset", "treefarm-split", ...).
The caller chooses the error type its users catch and a hint saying what the file should be or how to make it.
"""
from __future__ import annotations

import json

from species.errors import TreefarmError

from .schema import DatasetError
from .storage import Location

__all__ = ["parse_format_json", "read_format_json"]


def parse_format_json(text: str | bytes, file_format: str, *, source: str, hint: str,
                      error: type[TreefarmError] = DatasetError) -> dict:
    """The JSON object in `text` when its "format" is `file_format`; otherwise `error` naming `source` (the file, for
    the message), what was found and `hint`."""
    try:
        content = json.loads(text)
    except ValueError as exc:  # a JSONDecodeError, or bytes that are not UTF-8
        raise error(f"{source} is not valid JSON ({exc}): {hint}") from None
    if not isinstance(content, dict) or "format" not in content:
        raise error(f"{source} has no \"format\" key (allowed {file_format!r}): {hint}")
    if content["format"] != file_format:
        raise error(f"{source} has format {content['format']!r}, allowed {file_format!r}: {hint}")
    return content


def read_format_json(location: Location, name: str, file_format: str, *, hint: str,
                     error: type[TreefarmError] = DatasetError) -> dict:
    """The JSON object of the file `name` under `location` (`Location.resolve(folder)` for a local folder) when its
    "format" is `file_format`; `error` naming the folder or file and `hint` when the file is missing or is not that."""
    if not location.exists(name):
        raise error(f"{location.uri} has no {name}: {hint}")
    return parse_format_json(location.read_bytes(name), file_format, source=location.path(name), hint=hint, error=error)
