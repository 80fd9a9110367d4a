"""Benchmarks run by `vslam bench NAME` (listed in `vslam.bench.registry`): clients of the toolkit's public API that
build their inputs, call it and tabulate. Shared pieces: `timing` (repeated calls, medians), `results` (BenchResult,
JSON with the machine's description), `docs` (their tables in docs/benchmarks.md)."""
