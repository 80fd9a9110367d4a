"""Frame-to-frame motion for ground robots, and the floor geometry every package shares.

- `odometry.camera.CameraModel`: pinhole + distortion, pixel <-> floor mapping for a downward camera.
- `odometry.poses`: planar pose composition and TUM conversions.
- `odometry.footprint`: image footprints on the floor and their overlap J.
- `odometry.fusion`: wheel odometry + gyro EKF (filterpy) -> poses, covariances, relative motions.
"""
from odometry.camera import CameraModel
from odometry.footprint import footprint_overlap, footprint_polygon, overlap_matrix, overlap_pairs
from odometry.fusion import FusedTrajectory, FusionConfig, fuse_wheel_gyro
from odometry.poses import between, compose, integrate, inverse, relative_motions, wrap_angle

__all__ = ["CameraModel", "FusedTrajectory", "FusionConfig", "between", "compose", "footprint_overlap",
           "footprint_polygon", "fuse_wheel_gyro", "integrate", "inverse", "overlap_matrix", "overlap_pairs",
           "relative_motions", "wrap_angle"]
