"""vslam: visual SLAM with loop closure for ground robots.

The composition layer: sequence I/O, simulator, pipeline, evaluation, Rerun logging and the CLI.
`odometry`, `loops` and `graph` are standalone packages it composes.
"""
__version__ = "0.1.0"
