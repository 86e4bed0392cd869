"""Saying when the localization turns lost and found again (issue 22 item 14: a wrong
/initialpose with a tight covariance was kept silently). :class:`LostWatch` turns each
:class:`~.localizer.PoseEstimate` into a line on a change of state: ``lost: ...`` with why (the
scan's fit, the sigmas) and what to do, or ``localized``; the world node logs it and
publishes it latched on ``lowerbase/localization`` (std_msgs/String), which the tasks node
shows on robot_status. ROS-free."""

from __future__ import annotations

import math

from lowerbase.world.localization.localizer import PoseEstimate

LOCALIZED = "localized"


def describe_lost(est: PoseEstimate) -> str:
    """Why ``est`` reads lost, in one line, with what to do."""
    fit = "no beams to fit" if math.isnan(est.fit) else f"the scan fits the map at {est.fit:.0%}"
    return (f"lost: {fit}, sigma {est.sigma_xy:.2f} m / {math.degrees(est.sigma_yaw):.1f} deg "
            f"(a wrong /initialpose? publish a better one or call /global_localization)")


class LostWatch:
    """The localization's state as a line, given only when it changes (None otherwise)."""

    def __init__(self) -> None:
        self.state: str | None = None  #: the last line given

    def update(self, est: PoseEstimate) -> str | None:
        lost = est.lost
        if lost == (self.state is not None and self.state != LOCALIZED):
            return None  # the same state as last given
        self.state = describe_lost(est) if lost else LOCALIZED
        return self.state
