"""benchmarks.bench_reconstruct end to end on one tree per method: it prints every method's quality and stage
tables beside the papers' figures and writes the contact sheet. (Speed is measured there, not asserted here.)"""
from __future__ import annotations

from benchmarks import bench_reconstruct as bench


def test_one_tree_per_method_prints_every_table_and_writes_the_sheet(tmp_path, capsys):
    bench.main(["--trees", "1", "--sweep-trees", "1", "--sweep-views", "2", "--surface-samples", "500",
                "--sheet-trees", "1", "--out", str(tmp_path), "--no-results"])
    text = capsys.readouterr().out
    for method in bench.drawn_methods():
        assert f"{method}: quality on held-out trees" in text
        assert f"{method}: seconds per tree and stage" in text
    for figure in ("0.041", "0.032", "0.098", "~0.03", "7 s peach"):
        assert figure in text
    assert "rotation sweep, unit-cube Hausdorff" in text
    assert "failed" not in text
    sheet = tmp_path / "reconstructions.png"
    assert sheet.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bench_seeds_are_not_a_training_spec_seed():
    bench.check_seeds()  # raises SystemExit on a clash


def test_spread_covers_both_ends_of_a_mixed_species_list():
    names = [f"wp{i}" for i in range(14)] + [f"sc{i}" for i in range(24)]
    chosen = bench.spread(names, 12)
    assert len(chosen) == 12 and chosen[0] == "wp0" and chosen[-1] == "sc23"
    assert bench.spread(["a", "b"], 5) == ["a", "b", "a", "b", "a"]
