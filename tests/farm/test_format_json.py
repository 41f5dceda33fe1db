"""JSON files that name their format: a missing file, text that is not JSON and another format are refused with the
caller's error type, the file's name, what was found and the caller's hint."""
from __future__ import annotations

import json

import pytest

from farm.dataset import DatasetError, Location, parse_format_json, read_format_json, read_manifest
from species.errors import TreefarmError

HINT = "allowed a file `farm example` wrote"


class ExampleError(TreefarmError):
    """The error type a caller of the loader chooses."""


def write(folder, text: str) -> Location:
    (folder / "example.json").write_text(text)
    return Location.resolve(str(folder))


def test_a_file_of_the_format_reads_as_its_object(tmp_path):
    location = write(tmp_path, json.dumps({"format": "treefarm-example", "rows": [1, 2]}))
    assert read_format_json(location, "example.json", "treefarm-example", hint=HINT) == {
        "format": "treefarm-example", "rows": [1, 2]}


def test_a_missing_file_names_the_folder_and_the_file(tmp_path):
    with pytest.raises(ExampleError, match=f"^{tmp_path} has no example.json: {HINT}$"):
        read_format_json(Location.resolve(str(tmp_path)), "example.json", "treefarm-example", hint=HINT,
                         error=ExampleError)


@pytest.mark.parametrize("text, found", [
    ("{not json", r"is not valid JSON \(Expecting property name"),
    (b"\xff\xfe{", r"is not valid JSON \("),
    ('{"rows": []}', r'has no "format" key \(allowed \'treefarm-example\'\)'),
    ('[1, 2]', r'has no "format" key \(allowed \'treefarm-example\'\)'),
    ('{"format": "treefarm-other"}', r"has format 'treefarm-other', allowed 'treefarm-example'"),
])
def test_other_content_is_refused_naming_the_file_and_what_was_found(tmp_path, text, found):
    location = Location.resolve(str(tmp_path))
    (tmp_path / "example.json").write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ExampleError, match=f"^{tmp_path}/example.json {found}.*: {HINT}$"):
        read_format_json(location, "example.json", "treefarm-example", hint=HINT, error=ExampleError)


def test_parsed_text_names_its_source_and_the_default_error_is_a_dataset_error():
    with pytest.raises(DatasetError, match="^the registry's split has format 'x', allowed 'treefarm-split': h$"):
        parse_format_json('{"format": "x"}', "treefarm-split", source="the registry's split", hint="h")


def test_a_dataset_manifest_of_another_format_is_refused(tmp_path):
    (tmp_path / "manifest.json").write_text(json.dumps({"format": "treefarm-library"}))
    with pytest.raises(DatasetError, match="manifest.json has format 'treefarm-library', allowed 'treefarm-dataset'"):
        read_manifest(str(tmp_path))
