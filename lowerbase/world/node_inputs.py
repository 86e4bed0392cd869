"""The world node's inputs, ROS -> world: /odom and /initialpose, and the services
/start_localization, set_map and aic_map_server/get_map (docs/world.md, "ROS interface").
Mixed into :class:`~lowerbase.world.node.WorldNode`; rospy's callback threads call them, under
the node's lock. Bad input is a counted, logged drop or a failed service response, never an
exception out of a callback."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from lowerbase.errors import LowerbaseError, WorldError, count_drop

if TYPE_CHECKING:  # pragma: no cover
    from lowerbase.world.grid import OccupancyGrid
    from lowerbase.world.localization import Localizer
    from lowerbase.world.node_setup import Pose, WorldSetup
    from lowerbase.world.scan_odom import ScanOdom

log = logging.getLogger("lowerbase.world.node")  # the node's log, as before the split


class WorldInputs:
    """The node's subscribers and services; for the type checker, the node's state they use."""

    if TYPE_CHECKING:  # pragma: no cover
        rospy: Any
        io: Any
        wire: Any
        setup: WorldSetup
        lock: Any
        localizer: Localizer
        odom: Pose | None
        scan_odom: ScanOdom
        stats: dict[str, int]
        served_map: OccupancyGrid

        def _publish_map(self) -> None: ...

    def listen(self) -> tuple[list[Any], list[Any]]:
        """Subscribe /odom and /initialpose, serve the services: (subscribers, services)."""
        from geometry_msgs.msg import PoseWithCovarianceStamped
        from nav_msgs.msg import Odometry
        from nav_msgs.srv import GetMap, SetMap
        from std_srvs.srv import SetBool  # type: ignore[import-untyped]

        wire = self.wire
        subs = [wire.subscriber("/odom", Odometry, self._on_odom, queue_size=10),
                wire.subscriber("/initialpose", PoseWithCovarianceStamped,
                                self._on_initialpose, queue_size=2)]
        services = [wire.service("/start_localization", SetBool, self._start),
                    wire.service("set_map", SetMap, self._set_map),
                    wire.service("aic_map_server/get_map", GetMap, self._get_map)]
        return subs, services

    def _on_odom(self, msg: Any) -> None:
        try:
            pose = self.wire.convert(msg, self.io.ODOM_POSE, self.io.odom_pose)
        except WorldError as exc:
            self._count_bad("bad_odom", exc)
            return
        stamp = msg.header.stamp.to_sec()
        with self.lock:
            self.odom = pose
            self.scan_odom.add_odom(stamp if stamp > 0 else self.rospy.get_time(), pose)

    def _on_initialpose(self, msg: Any) -> None:
        try:
            if msg.header.frame_id.lstrip("/") not in ("", self.setup.map_frame):
                raise WorldError(f"/initialpose must be in the {self.setup.map_frame!r} frame, "
                                 f"got {msg.header.frame_id!r}")
            pose = self.io.pose_of(msg.pose.pose, "/initialpose")
            with self.lock:
                self.localizer.initial_pose(pose, self.io.covariance_of(msg))
        except LowerbaseError as exc:
            self._count_bad("bad_initialpose", exc)
            return
        log.info("localization re-initialised at (%.3f, %.3f, %.3f)", *pose)

    def _count_bad(self, key: str, exc: Exception) -> None:
        count_drop(self.stats, key, log, exc)

    def _start(self, req: Any) -> Any:
        from std_srvs.srv import SetBoolResponse

        with self.lock:
            ok, message = self.localizer.start(bool(req.data))
        return SetBoolResponse(success=ok, message=message)

    def _set_map(self, req: Any) -> Any:
        """nav_msgs/SetMap: the served map and the localizer's, all or nothing. Its response
        has no message field: the reason of a failure goes to the log (and /rosout)."""
        from nav_msgs.srv import SetMapResponse

        try:
            grid = self.io.grid_of(req.map)
            pose = self.io.pose_of(req.initial_pose.pose.pose, "set_map initial_pose")
            with self.lock:
                self.localizer.set_map(grid, pose, self.io.covariance_of(req.initial_pose))
                self.served_map = grid
                self._publish_map()
        except LowerbaseError as exc:
            log.warning("set_map refused, nothing changed: %s", exc)
            return SetMapResponse(success=False)
        log.info("set_map: new map %d x %d cells, robot at (%.3f, %.3f, %.3f)", grid.width,
                 grid.height, *pose)
        return SetMapResponse(success=True)

    def _get_map(self, req: Any) -> Any:
        from nav_msgs.srv import GetMapResponse

        with self.lock:
            grid = self.served_map
        return GetMapResponse(map=self.io.grid_msg(grid, self.rospy.Time.now(),
                                                   self.setup.map_frame))
