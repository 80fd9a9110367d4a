"""Many sequences at once (`vslam batch`): the function `vslam run` uses, mapped over a local process pool or a
Dask distributed cluster, resumable through OUT/batch.json, summarised across the fleet.

    from vslam.batch import run_many
    summary = run_many(["fleet/night-12/"], out="out/night-12")                # local pool, one process per CPU
    summary = run_many(["runs.csv"], cfg, client="tcp://10.0.0.5:8786", out="/shared/out")   # Dask cluster

Modules: inputs (what INPUTS name; manifest CSV), hashing (when a sequence is redone), task (one sequence on a
worker), pool and cluster (the engines), manifest (OUT/batch.json), summary (CSV, JSON, PNG), run (`run_many`).
"""
from vslam.batch.errors import BatchError
from vslam.batch.run import BatchProgress, run_many
from vslam.batch.summary import BatchSummary

__all__ = ["BatchError", "BatchProgress", "BatchSummary", "run_many"]
