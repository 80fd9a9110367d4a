"""Frame-to-frame motion for ground robots, and the floor geometry every package shares.

- `odometry.shared`: the primitives every package shares (pose math, rotations, TUM files, atomic writes,
  `CameraModel` and floor footprints, configuration, the error root); `loops` and `graph` import only these.
- `odometry.fusion`: wheel odometry + gyro EKF (filterpy) -> poses, covariances, relative motions.
- `odometry.vo`: downward-camera visual odometry (`VisualOdometry`, `run_visual_odometry`), built on
  `odometry.rigid` (Kabsch/SVD + RANSAC), `odometry.tilt_refine` and `odometry.tracking` (LK front end).
"""
from odometry.fusion import FusedTrajectory, FusionConfig, fuse_wheel_gyro
from odometry.rigid import RigidFit, kabsch_2d, ransac_rigid_2d
from odometry.shared.camera import CameraModel
from odometry.shared.footprint import footprint_overlap, footprint_polygon, overlap_matrix, overlap_pairs
from odometry.shared.poses import between, compose, integrate, inverse, relative_motions, wrap_angle
from odometry.vo import Method, VisualOdometry, VOConfig, VOEstimate, VOStatus, VOTrajectory, run_visual_odometry

__all__ = ["CameraModel", "FusedTrajectory", "FusionConfig", "Method", "RigidFit", "VOConfig", "VOEstimate", "VOStatus",
           "VOTrajectory", "VisualOdometry", "between", "compose", "footprint_overlap", "footprint_polygon",
           "fuse_wheel_gyro", "integrate", "inverse", "kabsch_2d", "overlap_matrix", "overlap_pairs",
           "ransac_rigid_2d", "relative_motions", "run_visual_odometry", "wrap_angle"]
