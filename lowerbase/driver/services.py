"""driver_base's services: operate the chassis from ROS (std_srvs, in the node's namespace).

Each service sends one ControlCommand to the lower computer (chassis.dbc ``ControlCommand``):

=====================  =================  =====================================================
service                type               ControlCommand
=====================  =================  =====================================================
``~enable``            std_srvs/Trigger   EnableCanControl (standby -> active)
``~standby``           std_srvs/Trigger   Standby (active -> standby: motion commands ignored)
``~estop``             std_srvs/SetBool   data true: EStopSet; false: EStopRelease (the chassis
                                          then waits in standby: call ``~enable``)
``~fault_clear``       std_srvs/Trigger   FaultClear (latched faults whose cause is gone)
``~odometer_reset``    std_srvs/Trigger   OdometerReset (the lower computer's total distance)
``~reboot``            std_srvs/Trigger   Reboot (the driver reconfigures; enables again
                                          unless the operator put it on hold, below)
=====================  =================  =====================================================

``success`` is true when the command went out, false (with the reason in ``message``) while
the link to the lower computer is not up, and for ``~enable`` while the chassis is e-stopped
("e-stopped: call ~estop false first"); the effect shows on ``status_code`` and
``~link_state``. An operator hold (``~estop true`` or ``~standby``) lasts until ``~enable``:
a reboot, even one asked for with ``~reboot``, does not end it (no automatic enable).
This module holds the table and the ROS-free decision; the node advertises.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from lowerbase.driver.core import DriverCore

#: service name (relative to the node: ``~name``) -> ControlCommand (Trigger services)
TRIGGERS: dict[str, str] = {
    "enable": "EnableCanControl",
    "standby": "Standby",
    "fault_clear": "FaultClear",
    "odometer_reset": "OdometerReset",
    "reboot": "Reboot",
}
#: the SetBool service: data true -> first command, false -> second
ESTOP = ("estop", "EStopSet", "EStopRelease")


def send_control(core: DriverCore, command: str) -> tuple[bool, str]:
    """Send ``command`` if the link is up: (success, message) for the service response."""
    if not core.link_up:
        core.stats["service_refused"] += 1
        return False, (f"{command} not sent: the lower computer link is {core.state.value} "
                       "(see ~link_state)")
    if command == "EnableCanControl" and core.e_stopped:
        core.stats["service_refused"] += 1
        return False, "e-stopped: call ~estop false first"
    core.control(command)
    core.stats[f"service_{command}"] += 1
    return True, f"{command} sent"


def advertise(wire: Any, core: DriverCore, lock: Any) -> list[Any]:
    """Create the services (after ``init_node``) through ``wire`` (:mod:`lowerbase.ros1.wire`:
    anything with ``service(name, cls, handler)``); each call holds ``lock`` around the
    core."""
    from std_srvs.srv import SetBool, Trigger  # type: ignore[import-untyped]

    # the response classes: ROS 1's ``TriggerResponse`` is ``Trigger._response_class``,
    # ROS 2's is ``Trigger.Response``
    TriggerResponse = getattr(Trigger, "Response", None) or Trigger._response_class
    SetBoolResponse = getattr(SetBool, "Response", None) or SetBool._response_class

    def trigger(command: str) -> Callable[[Any], Any]:
        def handle(_request: Any) -> Any:
            with lock:
                ok, text = send_control(core, command)
            return TriggerResponse(success=ok, message=text)
        return handle

    def estop(request: Any) -> Any:
        with lock:
            ok, text = send_control(core, ESTOP[1] if request.data else ESTOP[2])
        return SetBoolResponse(success=ok, message=text)

    services = [wire.service(f"~{name}", Trigger, trigger(command))
                for name, command in TRIGGERS.items()]
    services.append(wire.service(f"~{ESTOP[0]}", SetBool, estop))
    return services
