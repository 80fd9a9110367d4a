"""vslam: visual SLAM with loop closure for ground robots.

The composition layer: sequence I/O, simulator, pipeline, evaluation, Rerun logging and the CLI.
`odometry`, `loops` and `graph` are standalone packages it composes.
"""
__version__ = "0.1.0"


def __getattr__(name: str):
    """`vslam.Pipeline`, `vslam.PipelineConfig`, `vslam.open_sequence` without importing them at start-up."""
    if name in ("Pipeline", "PipelineConfig", "PipelineResult"):
        import vslam.pipeline as _p

        return getattr(_p, name)
    if name == "open_sequence":
        from vslam.io import open_sequence

        return open_sequence
    raise AttributeError(f"module 'vslam' has no attribute {name!r}")
