"""lowerbase.ros1.wire.publish_synchronously with a real rosmaster: a publisher made with a
small ``queue_size`` then swept writes each message on the publishing thread, so a burst far
larger than its queue reaches a subscriber whole and in order (rospy's queued connection drops
its oldest message whenever its writer thread is behind: the lockstep robot's outside
subscribers lost robot_state that way beside a CPU hog)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import ROOT
from tests.driver.conftest import require_ros, ros_master, woosh_msgs_build  # noqa: F401

BURST = '''
import json, sys, time
import rospy
from std_msgs.msg import UInt32
from lowerbase.ros1.wire import publish_synchronously
rospy.init_node("sync_probe", anonymous=True, disable_signals=True)
pub = rospy.Publisher("/sync_probe/n", UInt32, queue_size=1)
changed = publish_synchronously(rospy)
got = []
sub = rospy.Subscriber("/sync_probe/n", UInt32, lambda m: got.append(m.data))
end = time.monotonic() + 60.0  # a hang guard: the connection is made by rospy's threads
while pub.get_num_connections() == 0 and time.monotonic() < end:
    time.sleep(0.01)
kinds = [type(c).__name__ for c in pub.impl.connections]
for n in range(int(sys.argv[2])):
    pub.publish(UInt32(data=n))
while len(got) < int(sys.argv[2]) and time.monotonic() < end:
    time.sleep(0.01)
json.dump({"changed": changed, "kinds": kinds, "got": got}, open(sys.argv[1], "w"))
rospy.signal_shutdown("done")
'''


@pytest.mark.ros
@pytest.mark.process
def test_a_burst_larger_than_the_queue_arrives_whole_and_in_order(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    require_ros(("rospy", "std_msgs.msg"))
    script, out = tmp_path / "burst.py", tmp_path / "burst.json"
    script.write_text(BURST)
    n = 5000
    env = {**os.environ, **{k: v for k, v in ros_master.env.items() if k != "ROS_IP"},
           "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, str(script), str(out), str(n)], capture_output=True,
                         text=True, env=env, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(out.read_text())
    assert result["changed"] >= 1  # its own topic (and rosout's)
    assert result["kinds"] and "QueuedConnection" not in result["kinds"], result["kinds"]
    assert result["got"] == list(range(n))
