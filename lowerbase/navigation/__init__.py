"""Navigation on the emulated chassis: what ROS move_base does, as a ROS-free core on the
simulated clock plus a thin rospy/actionlib layer (the pattern of ``lowerbase.driver``).

One unit a module, split as ROS navigation is:

- ``costmap``: :class:`~lowerbase.navigation.costmap.LayeredCostmap` (costmap_2d's master
  grid and costs), the global costmap (static map + inflation) and the local rolling-window
  costmap (obstacles from /scan and the depth camera's cloud + inflation), set_footprint,
  enable_costmaps and clear_costmaps semantics, the footprint cost check.
- ``layers``: the costmap layers: static, obstacle (marking and ray-traced clearing) and
  inflation (a Euclidean distance transform).
- ``planner``: the global planner on the inflated costmap (/move_base/make_plan).
- ``controller``: the local controller following the plan within the driver's limits.
- ``steps``: /cmd_vel_control (StepControl) without ROS.
- ``navigator``: move_base's core: goals, replanning, stuck detection, preempt/cancel;
  ``modes``: /navigation_mode's fields; ``combined``: the costs it plans and drives on.
- ``sim``: :class:`~lowerbase.navigation.sim.NavSim`, a Navigator driving a WorldSim.
- ``node``: the rospy/actionlib layer.
"""
