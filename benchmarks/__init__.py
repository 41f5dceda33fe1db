"""Benchmarks: modules run as `python -m benchmarks.bench_NAME` that print timing and quality tables beside their
references and write `benchmarks/results/NAME.json` (`benchmarks.harness`); `make bench` runs the headline set
(`benchmarks.headline`) and regenerates docs/performance.md (`benchmarks.performance_doc`)."""
