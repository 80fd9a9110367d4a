"""Primitives every package shares: pose math, rotations, TUM files, atomic writes, the camera model and floor
geometry, configuration loading and the error root.

`odometry`, `loops`, `graph` and `vslam` all build on these modules; nothing in `odometry.shared` imports from
outside it, so taking only the loop detector or only the pose graph pulls in nothing else.

- `odometry.shared.poses`: planar poses (x, y, theta): compose, between, integrate, unicycle arcs.
- `odometry.shared.pose_covariance`: first-order covariance of compose / between.
- `odometry.shared.rotations`: quaternions (xyzw) and the camera tilt matrix.
- `odometry.shared.tum`: TUM trajectory files.
- `odometry.shared.atomic_io`: atomic file output.
- `odometry.shared.camera`: `CameraModel`, pinhole + distortion, pixel <-> floor mapping.
- `odometry.shared.footprint`: image footprints on the floor and their overlap J.
- `odometry.shared.errors`: `ToolkitError`, the root of every bad-input error.
"""
