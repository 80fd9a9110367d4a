"""Ground-texture simulator: downward-camera sequences over procedural floors made from real photographs.

    from vslam.sim import SimConfig, simulate
    simulate(SimConfig(floor="concrete", trajectory="figure8", length=20, seed=1), "out/seq")
"""
from vslam.sim.floor import NATURAL_FLOORS, Floor, FloorType
from vslam.sim.render import Effects
from vslam.sim.sensors import SensorNoise
from vslam.sim.simulate import SimConfig, SimResult, plan_motion, simulate
from vslam.sim.trajectory import TrajectoryKind

__all__ = ["Effects", "Floor", "FloorType", "NATURAL_FLOORS", "SensorNoise", "SimConfig", "SimResult",
           "TrajectoryKind", "plan_motion", "simulate"]
