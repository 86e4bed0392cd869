"""The world around the emulated chassis: maps, obstacles, sensors and localization.

This package sits above ``lowerbase.driver``: it reads the emulated robot's ground truth
through one explicit interface (:class:`lowerbase.world.truth.TruthSource`) and never reaches
into the firmware model. Everything here is a ROS-free core on an injected clock; the rospy
layer is a thin adapter, as in ``lowerbase.driver``.

Layout (one unit a module):

- ``grid``: :class:`OccupancyGrid`, the one representation of a 2D map (ROS conventions).
- ``maps``: map_server YAML + PGM/PNG reading/writing; the shipped map library by name
  (``maps/``: ``warehouse``, ``corridor_loop``, ``empty_room``, drawn by ``mapgen``).
- ``places``: named places (storage points ``mark_no``, the charger) in a map's sidecar.
- ``obstacles``: boxes and moving obstacles (people) the map does not know, with heights.
- ``footprint``: the robot's footprint polygon and contact tests against map and obstacles.
- ``lidar``, ``camera``: sensors ray-cast against the map and obstacles (numpy).
- ``localization``: a particle filter with a likelihood-field model (as amcl).
"""
