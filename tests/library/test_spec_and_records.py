"""The library spec as a pipeline spec (its tables, its job record) and the records a library folder keeps about
itself (library.json, added assets): round trips and rejections, no trees grown."""
from __future__ import annotations

import json

import pytest

from farm.jobs import DatasetTables, PipelineSpec
from farm.library.records import (LIBRARY_RECORD, LibraryError, library_asset_ids, read_library_spec,
                                  write_added_record, write_library_record)
from farm.library.spec import (FORMATS, LIBRARY_TABLES, LibrarySpecError, library_spec_from_record,
                               parse_library_spec)
from farm.dataset.storage import Location
from farm.tree_chain import tree_seed

SPEC = {"name": "records", "seed": 3, "species": {"maple": 2, "palm": 1}, "shard_size": 2}


def test_a_library_spec_is_a_pipeline_spec_with_no_views_and_no_glb_column():
    spec = parse_library_spec(SPEC)
    assert isinstance(spec, PipelineSpec)
    assert spec.tables == LIBRARY_TABLES == DatasetTables(view_outputs=(), store_glb=False)
    assert (spec.n_trees, spec.n_shards) == (3, 2)


def test_the_job_record_states_the_views_tables_outputs_as_a_job_specs_does():
    record = parse_library_spec(SPEC).to_dict()
    assert record["kind"] == "library"
    assert record["render"]["outputs"] == [] and record["store_glb"] is False


def test_a_spec_read_back_from_its_record_is_the_same_spec():
    spec = parse_library_spec(SPEC)
    assert library_spec_from_record(json.loads(json.dumps(spec.to_dict()))) == spec
    assert library_spec_from_record(spec.to_dict()).digest() == spec.digest()


def test_every_format_is_the_default():
    assert parse_library_spec({}).formats == FORMATS


@pytest.mark.parametrize("resources, named", [({"num_cpus": -1}, "resources.num_cpus"),
                                              ({"num_gpus": "one"}, "resources.num_gpus"),
                                              ({"memory": 2}, "resources.memory")])
def test_bad_resources_are_a_library_spec_error_naming_the_field(resources, named):
    with pytest.raises(LibrarySpecError) as info:
        parse_library_spec({**SPEC, "resources": resources})
    assert info.value.field == named and str(info.value).startswith("library spec field")


def test_library_record_round_trips_the_spec(tmp_path):
    location = Location.resolve(str(tmp_path))
    spec = parse_library_spec(SPEC)
    write_library_record(location, spec)
    assert read_library_spec(location) == spec
    assert json.loads((tmp_path / LIBRARY_RECORD).read_text())["spec_digest"] == spec.digest()


def test_a_folder_without_a_library_record_is_not_a_library(tmp_path):
    with pytest.raises(LibraryError, match="is not an asset library"):
        read_library_spec(Location.resolve(str(tmp_path)))


def test_asset_ids_are_the_specs_trees_and_the_added_ones_sorted(tmp_path):
    location = Location.resolve(str(tmp_path))
    spec = parse_library_spec(SPEC)
    planned = library_asset_ids(location, spec)
    assert len(planned) == 3 and planned == sorted(planned)
    assert f"palm-{tree_seed(3, 1):016x}" in planned  # species interleaved: the palm is tree 1
    write_added_record(location, "palm", 7)
    assert library_asset_ids(location, spec) == sorted([*planned, "palm-0000000000000007"])


def test_the_default_crossed_impostor_leaves_the_job_record_as_it_was():
    record = parse_library_spec(SPEC).to_dict()
    assert "impostor" not in record and "impostor_frames" not in record and record["impostor_tile"] == 128


def test_twig_cards_are_on_by_default_left_out_of_the_record_and_round_trip_when_off():
    spec = parse_library_spec(SPEC)
    assert spec.twig_cards is True and "twig_cards" not in spec.to_dict()
    assert parse_library_spec({**SPEC, "twig_cards": True}) == spec
    plain = parse_library_spec({**SPEC, "twig_cards": False})
    record = json.loads(json.dumps(plain.to_dict()))
    assert record["twig_cards"] is False and library_spec_from_record(record) == plain
    assert plain.digest() != spec.digest()


@pytest.mark.parametrize("value", ["no", 0, 1, None, [False]])
def test_twig_cards_other_than_true_or_false_are_refused_naming_the_value(value):
    with pytest.raises(LibrarySpecError) as info:
        parse_library_spec({**SPEC, "twig_cards": value})
    assert info.value.field == "twig_cards" and "true or false" in str(info.value) and repr(value) in str(info.value)


def test_an_octahedral_spec_takes_the_largest_tile_that_fits_the_atlas_and_round_trips():
    spec = parse_library_spec({**SPEC, "impostor": "octahedral"})
    assert (spec.impostor, spec.impostor_frames, spec.impostor_tile) == ("octahedral", 12, 85)
    assert parse_library_spec({**SPEC, "impostor": "octahedral", "impostor_frames": 6}).impostor_tile == 128
    record = json.loads(json.dumps(spec.to_dict()))
    assert record["impostor"] == "octahedral" and library_spec_from_record(record) == spec
    assert spec.digest() != parse_library_spec(SPEC).digest()
    sixteen = parse_library_spec({**SPEC, "impostor": "octahedral", "impostor_frames": 16})
    assert library_spec_from_record(sixteen.to_dict()) == sixteen and sixteen.impostor_tile == 64


@pytest.mark.parametrize("fields, named, allowed", [
    ({"impostor": "billboard"}, "impostor", "crossed, octahedral"),
    ({"impostor": "octahedral", "impostor_frames": 3}, "impostor_frames", "[4, 32]"),
    ({"impostor": "octahedral", "impostor_frames": 40}, "impostor_frames", "[4, 32]"),
    ({"impostor_frames": 12}, "impostor_frames", "only with impostor: octahedral"),
    ({"impostor": "octahedral", "impostor_tile": 128}, "impostor_tile", "at most 85 px with impostor_frames 12"),
    ({"impostor": "octahedral", "impostor_frames": 32, "impostor_tile": 33}, "impostor_tile",
     "at most 32 px with impostor_frames 32")])
def test_bad_impostor_fields_are_refused_naming_the_field_and_what_is_allowed(fields, named, allowed):
    with pytest.raises(LibrarySpecError) as info:
        parse_library_spec({**SPEC, **fields})
    assert info.value.field == named and allowed in str(info.value)
