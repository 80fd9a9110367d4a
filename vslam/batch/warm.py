"""What a worker imports before its first sequence: the modules a run loads on first use (Rerun, and pandas and
pyarrow when it logs; matplotlib's pyplot and Agg backend; filterpy), besides the pipeline itself.

The local pool's fork server imports this module once, so every sequence's process is forked warm: cold, those
imports cost a 2-second run about 3.5 s more. Dask workers are long-lived and pay it once; the benchmark
imports it on them before timing.
"""
from __future__ import annotations

import filterpy.kalman  # noqa: F401
import matplotlib.backends.backend_agg  # noqa: F401
import pyarrow  # noqa: F401
import rerun  # noqa: F401
import rerun.blueprint  # noqa: F401

import vslam.batch.task  # noqa: F401
from vslam.evaluation.plots import pyplot

try:   # Rerun uses pandas when it is installed; it is not one of its requirements
    import pandas  # noqa: F401
except ImportError:
    pass

pyplot()   # matplotlib with the Agg backend, chosen as the run's plots choose it
