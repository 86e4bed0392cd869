"""Navigation on the emulated chassis: what ROS move_base does, as a ROS-free core on the
simulated clock plus a thin rospy/actionlib layer (the pattern of ``lowerbase.driver``).

Planned layout (one unit a module, split as ROS navigation is):

- ``costmap``: :class:`~lowerbase.navigation.costmap.LayeredCostmap` (costmap_2d's master
  grid and costs), the global costmap (static map + inflation) and the local rolling-window
  costmap (obstacles from /scan and the depth camera's cloud + inflation), set_footprint,
  enable_costmaps and clear_costmaps semantics, the footprint cost check.
- ``layers``: the costmap layers: static, obstacle (marking and ray-traced clearing) and
  inflation (a Euclidean distance transform).
- ``planner``: the global planner on the inflated costmap (/move_base/make_plan).
- ``controller``: the local controller following the plan within the driver's limits.
- recovery behaviours (clear costmaps, rotate) and the actionlib servers (/move_base,
  /navigation_mode, /cmd_vel_control) in modules of their own.
"""
