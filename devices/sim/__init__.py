"""The simulated world: a plot of maize seedlings, foam spheres and checkerboards on uneven
soil, seen by a simulated Kinect v2 on a turntable on a mobile base.

- :mod:`devices.sim.scene` (with ``soil``, ``plants``, ``boards``): the world's meshes and truth;
  ``plants`` and ``plants_irregular`` are the two plant models (``--plant-model``).
- :mod:`devices.sim.rig`: stations, base, turntable and camera poses.
- :mod:`devices.sim.render`: ray casting into Kinect-like frames (colour, IR), with
  :mod:`devices.sim.sensor` (noise, artefacts, range) and :mod:`devices.sim.shadows`.
- :mod:`devices.sim.world`: :class:`SimWorld`, the live shared state the device simulators set.
- :mod:`devices.sim.survey`, :mod:`devices.sim.truth`: a simulated mission and its truth.
- :mod:`devices.sim.calibration_scenes`: boards for the calibration workflows;
  :mod:`devices.sim.visibility`: which boards a camera sees whole.
"""

from devices.sim.rig import Pose2D, RigGeometry
from devices.sim.world import SimWorld

__all__ = ["Pose2D", "RigGeometry", "SimWorld"]
