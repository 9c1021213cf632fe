"""Simulated two-arm high-five (paper Sec. IV, Fig. 5).

* :mod:`interprim.sim.arm` -- planar arms: forward kinematics, analytic
  Jacobians, inverse kinematics (:func:`observed_arm`: 2 links, shoulder and
  elbow hinges; :func:`controlled_arm`: 3 links, shoulder, elbow and wrist hinges).
* :mod:`interprim.sim.optimal_control` -- minimum-effort reaching with attractor
  points and a hard goal constraint (SLSQP).
* :mod:`interprim.sim.highfive` -- the interaction generator, the
  train/test split with held-out goal regions and :func:`highfive_recordings`
  (the same interactions as a lab would record them: the partner's hand in
  metres with tracker noise, the robot's joints).
* :mod:`interprim.sim.mujoco_arm` -- the robot as a torque-controlled MuJoCo
  arm answering a replayed partner live (extra ``[mujoco]``; not imported here).

Example
-------
>>> from interprim.sim import highfive_split
>>> train, test = highfive_split(100, 20, seed=0, progress=False)   # doctest: +SKIP
>>> train.demos[0].shape                                             # doctest: +SKIP
(171, 5)
"""

from .arm import PlanarArm, controlled_arm, observed_arm
from .highfive import (
    COLUMNS,
    GOAL_BOX,
    RECORDING_COLUMNS,
    HighFiveData,
    generate_highfive,
    highfive_recordings,
    highfive_split,
    in_test_region,
)
from .optimal_control import ReachSolution, TrajectoryBasis, solve_reach

__all__ = [
    "PlanarArm",
    "observed_arm",
    "controlled_arm",
    "solve_reach",
    "ReachSolution",
    "TrajectoryBasis",
    "HighFiveData",
    "generate_highfive",
    "highfive_split",
    "in_test_region",
    "GOAL_BOX",
    "COLUMNS",
    "RECORDING_COLUMNS",
    "highfive_recordings",
]
