"""Job specs: YAML round trip, one clear error per bad field, species split and interleaving."""
from __future__ import annotations

import pytest
import yaml

from farm.jobs import (DatasetTables, JobSpecError, check_int, check_resources, default_spec, load_spec, parse_spec,
                       species_of_trees, spec_to_yaml)
from farm_standins import OUTPUTS, SPECIES, standin_spec

KNOWN = dict(known_species=SPECIES, known_outputs=OUTPUTS)


def test_spec_round_trips_through_yaml(tmp_path):
    spec = standin_spec()
    path = tmp_path / "job.yaml"
    path.write_text(spec_to_yaml(spec))
    assert load_spec(path, **KNOWN) == spec


@pytest.mark.parametrize("field, value, named", [
    ("species", {"no_such_tree": 2}, "species.no_such_tree"),
    ("species", {"standin_a": -1}, "species.standin_a"),
    ("seed", -3, "seed"),
    ("shard_size", 0, "shard_size"),
    ("max_nodes", 0, "max_nodes"),
    ("trees", "many", "trees"),
    ("render", {"outputs": ["oil_painting"]}, "render.outputs"),
    ("render", {"rig": "circle"}, "render.rig"),
    ("render", {"size": 3}, "render.size"),
    ("colour", "red", "colour"),
])
def test_bad_field_raises_one_error_naming_it(field, value, named):
    with pytest.raises(JobSpecError) as info:
        standin_spec(**{field: value})
    assert info.value.field == named
    assert len(str(info.value).splitlines()) == 1


def test_total_trees_are_split_by_weight_and_sum_to_total():
    spec = standin_spec(species={"standin_a": 2.0, "standin_b": 1.0}, trees=10)
    assert spec.species_counts == {"standin_a": 7, "standin_b": 3}
    assert spec.n_trees == 10


def test_with_trees_overrides_the_total_evenly():
    spec = standin_spec().with_trees(4)
    assert spec.species_counts == {"standin_a": 2, "standin_b": 2}


def test_species_are_interleaved_over_the_index_range():
    spec = standin_spec(species={"standin_a": 4, "standin_b": 4})
    species = species_of_trees(spec)
    assert sorted(species) == ["standin_a"] * 4 + ["standin_b"] * 4
    assert all(species[i] != species[i + 1] for i in range(len(species) - 1))


def test_digest_ignores_output_location_and_resources_only():
    spec = standin_spec()
    assert standin_spec(output="/elsewhere", resources={"num_cpus": 2}).digest() == spec.digest()
    assert standin_spec(seed=8).digest() != spec.digest()


def test_invalid_yaml_file_is_a_spec_error(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("species: [unclosed\n")
    with pytest.raises(JobSpecError, match="valid YAML"):
        load_spec(path, **KNOWN)


def test_default_spec_has_every_preset_and_the_default_outputs():
    import renderers
    import species
    from farm.jobs import default_spec

    spec = default_spec()
    assert list(spec.species) == [p.name for p in species.list_presets()]
    assert spec.render.outputs == tuple(renderers.DEFAULT_OUTPUTS)
    assert (spec.render.rig, spec.render.size) == ("tsn4", 256)
    assert yaml.safe_load(spec_to_yaml(spec))["shard_size"] == 8


def test_kuberay_job_manifest_carries_a_valid_job_spec():
    from pathlib import Path

    from farm.jobs import parse_spec

    manifest = Path(__file__).resolve().parents[2] / "infra/kuberay/rayjob.yaml"
    config_map = next(d for d in yaml.safe_load_all(manifest.read_text()) if d["kind"] == "ConfigMap")
    spec = parse_spec(yaml.safe_load(config_map["data"]["job.yaml"]))
    assert spec.n_trees == 20000


def test_print_spec_gives_yaml_that_loads_back_to_the_default_job(tmp_path, capsys):
    from farm.cli import main
    from farm.jobs import default_spec

    assert main(["generate", "--print-spec"]) == 0
    path = tmp_path / "default.yaml"
    path.write_text(capsys.readouterr().out)
    assert load_spec(path) == default_spec()


def test_trees_option_overrides_the_total_in_the_printed_spec(capsys):
    from farm.cli import main

    assert main(["generate", "--trees", "5", "--print-spec"]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["trees"] == 5 and all(weight == 1.0 for weight in printed["species"].values())


def test_the_tables_of_a_job_are_its_render_outputs_and_its_glb_choice():
    assert standin_spec().tables == DatasetTables(view_outputs=OUTPUTS, store_glb=False)
    assert standin_spec(store_glb=True, render={"outputs": ["mask"]}).tables == DatasetTables(("mask",), True)


def test_resources_default_to_one_cpu_and_no_gpu():
    assert check_resources({}) == {"num_cpus": 1.0, "num_gpus": 0.0}
    assert standin_spec(resources={"num_gpus": 0.5}).resources == {"num_cpus": 1.0, "num_gpus": 0.5}


def test_worker_memory_is_given_in_gib_and_a_too_small_one_is_refused():
    assert check_resources({"memory_gb": 4})["memory_gb"] == 4.0
    for value in (0.2, -1, "4G", True):
        with pytest.raises(JobSpecError) as info:
            check_resources({"memory_gb": value})
        assert info.value.field == "resources.memory_gb" and ">= 1.0" in str(info.value)


@pytest.mark.parametrize("value", [True, 2.5, "3", -1, 11])
def test_check_int_names_the_field_and_its_range(value):
    with pytest.raises(JobSpecError) as info:
        check_int("shard_size", value, 0, 10)
    assert info.value.field == "shard_size" and info.value.value == value


def test_a_small_job_of_the_default_spec_samples_every_generator():
    import species

    generators = {p.name: p.generator for p in species.list_presets()}
    counts = default_spec().with_trees(12).species_counts
    assert sum(counts.values()) == 12 and max(counts.values()) == 1
    assert {generators[name] for name, count in counts.items() if count} == set(generators.values())


def test_with_trees_leaves_the_full_default_job_as_it_was():
    spec = default_spec()
    assert spec.with_trees(spec.n_trees).species_counts == spec.species_counts


@pytest.mark.parametrize("fields, named", [({"trees": 0}, "trees"),
                                           ({"species": {name: 0 for name in SPECIES}}, "species")])
def test_a_job_of_zero_trees_is_refused(fields, named):
    with pytest.raises(JobSpecError) as info:
        standin_spec(**fields)
    assert info.value.field == named


def test_with_trees_refuses_zero():
    with pytest.raises(JobSpecError, match="trees"):
        standin_spec().with_trees(0)
