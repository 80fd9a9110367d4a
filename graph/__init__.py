"""GTSAM pose-graph back end: odometry and loop factors, robust loop handling, LAGO / LM / iSAM2, g2o and TORO I/O.

    from graph import RobustPoseGraph, GraphParams
    g = RobustPoseGraph()                             # planar; dim=3 for Pose3; strategy="isam2" for online use
    g.add_node(0, [0, 0, 0]); g.add_node(1)
    g.add_odometry(0, 1, [1, 0, 0.1], cov)            # delta = x_0^-1 x_1, cov 3x3 in (x, y, theta)
    k = g.add_loop(1, 0, delta, cov, probability=0.95)
    ids, poses = g.update()                           # current estimate (batch: robust solve; iSAM2: insert)
    res = g.result()                                  # res.poses (N, 3), res.loop_inlier[k], res.summary()

`RobustPoseGraph` is the front door; `PoseGraph` (batch) and `IncrementalPoseGraph` (iSAM2) are its strategies. `read_graph` / `write_graph` read and write g2o and TORO files; `optimize(data, params)`
solves a `PoseGraphData`. See docs/graph.md for the design and the measurements behind the defaults.
"""
from graph.formats import (
                           GraphFormatError,
                           format_g2o,
                           format_toro,
                           read_g2o,
                           read_graph,
                           read_toro,
                           write_graph,
                           write_toro,
)
from graph.incremental import IncrementalPoseGraph
from graph.model import PoseGraphData, classify_edges
from graph.optimizer import optimize
from graph.outliers import LoopScores, inject_false_loops, loop_scores
from graph.params import (
                           GncImpl,
                           GncLoss,
                           GraphParams,
                           IncrementalParams,
                           InitMethod,
                           LoopWeighting,
                           RobustMode,
                           RobustParams,
                           Solver,
                           SolverParams,
)
from graph.pose_graph import PoseGraph
from graph.result import GraphResult, write_g2o, write_tum
from graph.robust_graph import RobustPoseGraph

__all__ = ["GncImpl", "GncLoss", "GraphFormatError", "GraphParams", "GraphResult", "IncrementalParams",
           "IncrementalPoseGraph", "InitMethod", "LoopScores", "LoopWeighting", "PoseGraph", "PoseGraphData",
           "RobustMode", "RobustParams", "RobustPoseGraph", "Solver", "SolverParams",
           "classify_edges", "format_g2o", "format_toro", "inject_false_loops", "loop_scores", "optimize",
           "read_g2o", "read_graph", "read_toro", "write_g2o", "write_graph", "write_toro", "write_tum"]
