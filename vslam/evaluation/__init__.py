"""Evaluation: APE/RPE with evo's conventions, start-to-end error, loop precision/recall, plots."""
from vslam.evaluation.metrics import (
                                      Alignment,
                                      DeltaUnit,
                                      PoseRelation,
                                      TrajectoryReport,
                                      align,
                                      ape,
                                      associate,
                                      evaluate,
                                      rpe,
                                      start_to_end_error,
                                      statistics,
)

__all__ = ["Alignment", "DeltaUnit", "PoseRelation", "TrajectoryReport", "align", "ape", "associate", "evaluate",
           "rpe", "start_to_end_error", "statistics"]
