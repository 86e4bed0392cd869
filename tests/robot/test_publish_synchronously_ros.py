"""lowerbase.ros1.wire.publish_synchronously with a real rosmaster: a publisher made with a
small ``queue_size`` then swept writes each message on the publishing thread, so a burst far
larger than its queue reaches a subscriber whole and in order (rospy's queued connection drops
its oldest message whenever its writer thread is behind: the lockstep robot's outside
subscribers lost robot_state that way beside a CPU hog). A subscriber that reads no more then
holds the publisher: lowerbase.ros1.held names it and lets go of it."""

from __future__ import annotations

import json
import os
import signal
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


READER = '''
import os, signal
import rospy
from std_msgs.msg import String
rospy.init_node("held_probe_reader", disable_signals=True)
first = [True]
def stop_reading(msg):  # at the first message this process stops, as a debugger would
    if first[0]:
        first[0] = False
        os.kill(os.getpid(), signal.SIGSTOP)
rospy.Subscriber("/held_probe/big", String, stop_reading, queue_size=1)
rospy.spin()
'''

FLOOD = '''
import json, os, signal, sys, threading, time
import rospy
from std_msgs.msg import String
from lowerbase.ros1.held import backlogs
from lowerbase.ros1.wire import publish_synchronously
rospy.init_node("held_probe", disable_signals=True)
pub = rospy.Publisher("/held_probe/big", String, queue_size=1)
publish_synchronously(rospy)
end = time.monotonic() + 120.0  # hang guards: rospy's threads make the connection
while pub.get_num_connections() == 0 and time.monotonic() < end:
    time.sleep(0.01)
idle = backlogs(rospy)  # connected, nothing sent: no backlog
def flood():  # 13 MB: more than the socket buffers of a reader that stopped (~4 MB)
    for _ in range(200):
        pub.publish(String(data="x" * 65536))
writer = threading.Thread(target=flood, daemon=True)
writer.start()
found = []
while not found and writer.is_alive() and time.monotonic() < end:
    found = backlogs(rospy, 64 * 1024)
    time.sleep(0.05)
held = writer.is_alive()
os.kill(int(sys.argv[2]), signal.SIGCONT)  # the reader reads again
writer.join(120.0)
after = backlogs(rospy)
while after and time.monotonic() < end:  # sendall returned: the reader still drains its socket
    time.sleep(0.05)
    after = backlogs(rospy)
json.dump({"idle": [str(b) for b in idle], "found": [(b.topic, b.subscriber, b.unsent)
           for b in found], "text": [str(b) for b in found], "held": held,
           "writer_ended": not writer.is_alive(), "after": [str(b) for b in after]},
          open(sys.argv[1], "w"))
rospy.signal_shutdown("done")
'''


@pytest.mark.ros
@pytest.mark.process
def test_a_subscriber_that_reads_no_more_is_named(
        ros_master: Any, tmp_path: Path) -> None:  # noqa: F811
    """The reader stops itself at its first message; the flood's publishing thread then waits
    in sendall, and backlogs() names the reader's connection by its unsent bytes (what the
    lockstep robot's hold warning says). Continued, the reader takes it all: the writer ends
    and no backlog is left."""
    require_ros(("rospy", "std_msgs.msg"))
    env = {**os.environ, **{k: v for k, v in ros_master.env.items() if k != "ROS_IP"},
           "PYTHONPATH": str(ROOT)}
    (tmp_path / "reader.py").write_text(READER)
    (tmp_path / "flood.py").write_text(FLOOD)
    reader = subprocess.Popen([sys.executable, str(tmp_path / "reader.py")], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        out = tmp_path / "flood.json"
        run = subprocess.run([sys.executable, str(tmp_path / "flood.py"), str(out),
                              str(reader.pid)], capture_output=True, text=True, env=env,
                             timeout=400)
        assert run.returncode == 0, run.stderr[-3000:]
        result = json.loads(out.read_text())
    finally:
        reader.send_signal(signal.SIGCONT)
        reader.kill()
        reader.wait(timeout=30)
    assert result["idle"] == []
    assert result["held"], result  # the writer waited when the backlog was seen
    [(topic, subscriber, unsent)] = result["found"]
    assert (topic, subscriber) == ("/held_probe/big", "/held_probe_reader")
    assert unsent >= 64 * 1024
    assert result["text"][0].startswith("/held_probe/big -> /held_probe_reader (")
    assert result["writer_ended"] and result["after"] == [], result
