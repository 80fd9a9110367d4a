"""Benchmarks run by `vslam bench NAME`; shared helpers in `vslam.bench._common`."""
