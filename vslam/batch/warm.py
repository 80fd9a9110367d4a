"""What a worker imports before its first sequence: the modules a run loads on first use (Rerun with pandas and
pyarrow, matplotlib's pyplot, filterpy), besides the pipeline itself.

The local pool's fork server imports this module once, so every sequence's process is forked warm: cold, those
imports cost a 2-second run about 3.5 s more. Dask workers are long-lived and pay it once; the benchmark
imports it on them before timing.
"""
from __future__ import annotations

import filterpy.kalman  # noqa: F401
import rerun  # noqa: F401
import rerun.blueprint  # noqa: F401

import vslam.batch.task  # noqa: F401
from vslam.evaluation.plots import pyplot

pyplot()   # matplotlib with the Agg backend, chosen as the run's plots choose it
