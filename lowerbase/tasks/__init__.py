"""Tasks on the emulated chassis: exec_task, robot_status, charging (docs/tasks.md).

- ``model``: the seed's codes (task_exect, task_type, task_state, action_type, action_state,
  robot_state) and ExecTask / RobotStatus without ROS;
- ``plan``: execute requests checked against the map's places, turned into actions;
- ``status``: robot_state from the chassis and the task; robot_status only on change;
- ``machine``: the task state machine (its tick), with ``requests`` (exec_task), ``docking``
  (dock in / out), ``blocked`` (the path-blocked warning) and ``task`` (a task, navigation).
"""
