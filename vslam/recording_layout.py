"""Where things live in a run's Rerun recording and how the viewer opens it: entity paths, colours, the blueprint.

Entities (timelines `frame` and `time`; Rerun's convention: static ViewCoordinates on the world, the image and its
Pinhole under the camera's transform):
    /world                                   RIGHT_HAND_Z_UP, metres; /world/floor is the floor plane (z = 0)
    /world/robot                             the robot's pose (SLAM when running, else VO) as a Transform3D
    /world/robot/footprint                   the camera footprint on the floor (static, moves with the robot)
    /world/robot/camera                      the camera mount (height, mount yaw, looking down)
    /world/robot/camera/image                Pinhole + downscaled JPEG; /keypoints and VO inlier /matches on it
    /world/trajectory/{vo,slam}/<k>          line strips; SLAM is redrawn whenever the graph is optimised
    /world/trajectory/gt                     ground truth (static), when the sequence has one
    /world/loops/{kept,rejected}             loops accepted by the detector, kept / rejected by the robust back
                                             end: an arc between the two poses and a ring around the query pose
    /world/loops/candidates                  verified candidates below the detector's threshold (hidden by default)
    /metrics/vo/*, /metrics/loops/*, /metrics/timing/*   time series, one plot per unit in the blueprint
    /log                                     text events (loops closed, tracking lost)
"""
from __future__ import annotations

import numpy as np

ROBOT = "/world/robot"
FOOTPRINT = "/world/robot/footprint"
CAMERA = "/world/robot/camera"
IMAGE = "/world/robot/camera/image"
KEYPOINTS = IMAGE + "/keypoints"
MATCHES = IMAGE + "/matches"
FLOOR = "/world/floor"
TRAJECTORY = "/world/trajectory"
LOOPS = "/world/loops"
LOG = "/log"

GREEN, RED, GREY, YELLOW = (40, 190, 60), (230, 40, 40), (150, 150, 150), (250, 200, 0)
COLOURS = {"vo": (255, 140, 0), "slam": (30, 120, 230), "gt": (90, 90, 90)}
LOOP_COLOURS = {"kept": GREEN, "rejected": RED, "candidates": GREY}

# Time series grouped by unit: values of different units on one axis hide each other (inliers 0-200 beside
# probabilities 0-1). (entity under /metrics, legend name) per plot.
SERIES = {
    "VO inliers (count)": [("vo/inliers", "VO inliers")],
    "ratios and probabilities (0-1)": [("vo/inlier_ratio", "VO inlier ratio"),
                                       ("loops/probability", "P(loop | score)")],
    "loop scores (score units)": [("loops/local_score", "local score"), ("loops/global_score", "global score")],
    "time per frame (ms)": [("timing/vo_ms", "VO"), ("timing/loops_ms", "loops"), ("timing/graph_ms", "graph"),
                            ("timing/frame_ms", "whole frame")],
}


def eye_for(bounds: np.ndarray | None):
    """A 3D eye looking obliquely down at the scene's (xmin, ymin, xmax, ymax) box, or None (viewer's default)."""
    import rerun.blueprint as rrb

    if bounds is None or not np.all(np.isfinite(bounds)):
        return None
    x0, y0, x1, y1 = (float(v) for v in bounds)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    r = max(x1 - x0, y1 - y0, 0.5)
    # from the south, about 55 degrees above the floor: the trajectory reads as a map, the frustum keeps its depth
    return rrb.EyeControls3D(position=[cx, cy - 0.55 * r, 0.8 * r], look_target=[cx, cy + 0.03 * r, 0.0],
                             eye_up=[0, 0, 1])


def blueprint(bounds: np.ndarray | None = None):
    """The default layout: the 3D scene (with the event log under it) | the camera image over the time series."""
    import rerun.blueprint as rrb

    plots = [rrb.TimeSeriesView(origin="/metrics", name=name,
                                contents=[f"/metrics/{path}" for path, _ in series],
                                plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop))
             for name, series in SERIES.items()]
    scene = rrb.Spatial3DView(
        origin="/world", name="3D scene",
        overrides={f"{LOOPS}/candidates": rrb.EntityBehavior(visible=False)},
        eye_controls=eye_for(bounds),
        line_grid=rrb.LineGrid3D(visible=False))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(scene, rrb.TextLogView(origin=LOG, name="events"), row_shares=[5, 1]),
            rrb.Vertical(rrb.Spatial2DView(origin=IMAGE, name="camera image"),
                         rrb.Grid(*plots, grid_columns=2), row_shares=[3, 4]),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )
