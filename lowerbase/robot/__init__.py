"""The whole virtual robot in one command (``lowerbase robot``): a supervisor of the parts'
processes (:mod:`lowerbase.robot.supervisor`), the ROS master (:mod:`lowerbase.robot.master`)
and what is started in which order (:mod:`lowerbase.robot.plan`)."""
