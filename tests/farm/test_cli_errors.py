"""The CLI's error rules: a user's error is one line and status 2, a bug its traceback, a report line and status 1;
`--debug` shows a user error's traceback; a user's error raised in a Ray worker arrives as its own one line."""
from __future__ import annotations

from functools import partial

import pytest

import farm.pipeline
from farm.cli import BUG_REPORT, main
from farm.commands import species as species_command
from farm.commands import tree as tree_command
from farm.jobs import parse_spec, spec_to_yaml
from farm_standins import REFUSAL, broken_chain, refusing_chain, standin_spec
from species.errors import ParameterError


def stderr_lines(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("argv, named", [
    (["species", "--generator", "fractal"], "unknown generator 'fractal'"),
    (["tree", "--params", "{tmp}/absent.json", "--out", "{tmp}/out"], "absent.json is missing"),
    (["tree", "--species", "maple", "--out", "{tmp}"], "is a folder"),
    (["status", "{tmp}"], "holds no treefarm job"),
    (["status", "nosuchfs://bucket/data"], "not a path or a file system URI"),
    (["inspect", "{tmp}"], "no manifest.json"),
    (["export", "{tmp}", "--format", "stl", "--out", "{tmp}/out"], "allowed glb, obj"),
    (["render", "--species", "maple", "--size", "4", "--out", "{tmp}/views"], "--size 4 is out of range"),
    (["library", "validate"], "needs the library folder"),
    (["generate", "{tmp}/absent.yaml", "--out", "{tmp}/out"], "absent.yaml"),
])
def test_a_bad_value_is_one_line_and_status_2(tmp_path, capsys, argv, named):
    status = main([word.format(tmp=tmp_path) for word in argv])
    lines = stderr_lines(capsys)
    assert status == 2 and len(lines) == 1, lines
    assert lines[0].startswith("farm: error: ") and named in lines[0]


def test_a_file_error_of_a_path_on_the_command_line_is_one_line(tmp_path, capsys, monkeypatch):
    target = tmp_path / "trees" / "maple.glb"

    def refuse(mesh, path, fmt):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(tree_command, "write_tree", refuse)
    assert main(["tree", "--species", "maple", "--out", str(target)]) == 2
    assert stderr_lines(capsys) == [f"farm: error: {target}: Permission denied"]


def test_an_output_location_that_is_a_file_is_one_line_naming_it(tmp_path, capsys):
    (tmp_path / "taken").write_text("not a folder")
    assert main(["generate", "--trees", "2", "--out", str(tmp_path / "taken"), "--quiet"]) == 2
    lines = stderr_lines(capsys)
    assert len(lines) == 1 and lines[0].startswith(f"farm: error: cannot write {tmp_path / 'taken'}/")


def test_a_file_error_of_a_path_the_user_never_named_is_a_bug(tmp_path, capsys, monkeypatch):
    def refuse(mesh, path, fmt):
        raise FileNotFoundError(2, "No such file or directory", "/usr/share/treefarm/missing-table.bin")

    monkeypatch.setattr(tree_command, "write_tree", refuse)
    assert main(["tree", "--species", "maple", "--out", str(tmp_path / "maple.glb")]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1] == BUG_REPORT


@pytest.mark.parametrize("module, name, error, argv", [
    (tree_command, "grow_tree", KeyError("stage_seconds"), ["tree", "--species", "maple", "--out", "{tmp}/m.glb"]),
    (species_command, "format_table", ValueError("column widths disagree"), ["species"]),
])
def test_an_internal_error_prints_its_traceback_and_asks_for_a_report(tmp_path, capsys, monkeypatch,
                                                                      module, name, error, argv):
    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(module, name, fail)
    assert main([word.format(tmp=tmp_path) for word in argv]) == 1
    lines = stderr_lines(capsys)
    assert lines[0] == "Traceback (most recent call last):"
    assert any(line.startswith(type(error).__name__) and str(error.args[0]) in line for line in lines)
    assert lines[-1] == BUG_REPORT and not any(line.startswith("farm: error:") for line in lines)


def test_debug_prints_the_traceback_of_a_user_error_and_keeps_its_status(capsys):
    assert main(["--debug", "species", "--generator", "fractal"]) == 2
    lines = stderr_lines(capsys)
    assert lines[0] == "Traceback (most recent call last):" and any("CommandLineError" in line for line in lines)
    assert lines[-1].startswith("farm: error: unknown generator 'fractal'")


def test_an_interrupt_is_status_130(tmp_path, capsys, monkeypatch):
    def interrupt(params):
        raise KeyboardInterrupt

    monkeypatch.setattr(tree_command, "grow_tree", interrupt)
    assert main(["tree", "--species", "maple", "--out", str(tmp_path / "m.glb")]) == 130
    assert stderr_lines(capsys) == ["farm: interrupted"]


def test_a_usage_error_stays_argparse_s(capsys):
    with pytest.raises(SystemExit) as exited:
        main(["tree", "--species", "maple"])
    assert exited.value.code == 2 and "the following arguments are required: --out" in capsys.readouterr().err


def test_a_user_error_raised_in_a_worker_reaches_the_driver_as_itself(ray_session, tmp_path):
    with pytest.raises(ParameterError) as caught:
        farm.pipeline.run_job(standin_spec(), str(tmp_path), workers=1, builder_factory=refusing_chain,
                              progress=False)
    assert type(caught.value) is ParameterError and str(caught.value) == str(REFUSAL)
    assert (caught.value.key, caught.value.value, caught.value.allowed) == (REFUSAL.key, REFUSAL.value, REFUSAL.allowed)


@pytest.fixture
def one_shard_spec(tmp_path):
    path = tmp_path / "job.yaml"
    path.write_text(spec_to_yaml(parse_spec({"name": "refused", "seed": 1, "shard_size": 2, "species": {"maple": 2},
                                             "render": {"rig": "two-view", "size": 32}})))
    return path


def test_farm_generate_prints_a_worker_s_user_error_as_its_one_line(ray_session, one_shard_spec, tmp_path, capsys,
                                                                     monkeypatch):
    monkeypatch.setattr(farm.pipeline, "run_job", partial(farm.pipeline.run_job, builder_factory=refusing_chain))
    assert main(["generate", str(one_shard_spec), "--out", str(tmp_path / "out"), "--workers", "1", "--quiet"]) == 2
    assert stderr_lines(capsys) == [f"farm: error: {REFUSAL}"]


def test_farm_generate_prints_a_worker_s_bug_with_the_worker_s_traceback(ray_session, one_shard_spec, tmp_path,
                                                                         capsys, monkeypatch):
    monkeypatch.setattr(farm.pipeline, "run_job", partial(farm.pipeline.run_job, builder_factory=broken_chain))
    assert main(["generate", str(one_shard_spec), "--out", str(tmp_path / "out"), "--workers", "1", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "standin_lookup_table" in err and "broken_chain" in err
    assert err.strip().splitlines()[-1] == BUG_REPORT
