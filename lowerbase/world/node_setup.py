"""What the world node needs, checked without ROS: :class:`WorldSetup` (built by
``lowerbase.cli.world`` and the lockstep robot before rospy starts; used by
:mod:`lowerbase.world.node` and :mod:`lowerbase.world.node_inputs`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from lowerbase.world.footprint import validate_pose
from lowerbase.world.grid import OccupancyGrid
from lowerbase.world.obstacles import Obstacles
from lowerbase.world.sensors import SensorsConfig

Pose = tuple[float, float, float]


@dataclass
class WorldSetup:
    """Everything the node needs, checked without ROS (see ``lowerbase.cli.world``)."""

    grid: OccupancyGrid
    sensors: SensorsConfig
    start: Pose  #: the emulator's origin on the map (where its robot starts)
    obstacles: Obstacles = field(default_factory=Obstacles)
    ground_truth: bool = False
    camera: bool = True
    map_frame: str = "map"
    odom_frame: str = "odom"
    base_frame: str = "base_link"
    seed: int = 0

    def __post_init__(self) -> None:
        self.start = validate_pose(self.start, self.grid, self.obstacles, 0.0,
                                   what="the robot's start pose")
