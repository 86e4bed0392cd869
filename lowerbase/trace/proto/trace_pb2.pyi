from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class GTracePoint(_message.Message):
    __slots__ = ("x", "y", "angle", "speed", "starter")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    ANGLE_FIELD_NUMBER: _ClassVar[int]
    SPEED_FIELD_NUMBER: _ClassVar[int]
    STARTER_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    angle: float
    speed: int
    starter: int
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., angle: _Optional[float] = ..., speed: _Optional[int] = ..., starter: _Optional[int] = ...) -> None: ...

class GTraceSeg(_message.Message):
    __slots__ = ("first", "second", "finished")
    FIRST_FIELD_NUMBER: _ClassVar[int]
    SECOND_FIELD_NUMBER: _ClassVar[int]
    FINISHED_FIELD_NUMBER: _ClassVar[int]
    first: GTracePoint
    second: GTracePoint
    finished: float
    def __init__(self, first: _Optional[_Union[GTracePoint, _Mapping]] = ..., second: _Optional[_Union[GTracePoint, _Mapping]] = ..., finished: _Optional[float] = ...) -> None: ...

class GTraceList(_message.Message):
    __slots__ = ("lists", "map", "status")
    class ExecuteStatus(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
        __slots__ = ()
        EXECUTE_STATUS_IDLE: _ClassVar[GTraceList.ExecuteStatus]
        EXECUTE_STATUS_RUNNING: _ClassVar[GTraceList.ExecuteStatus]
        EXECUTE_STATUS_BLOCKED: _ClassVar[GTraceList.ExecuteStatus]
        EXECUTE_STATUS_FINISHED: _ClassVar[GTraceList.ExecuteStatus]
    EXECUTE_STATUS_IDLE: GTraceList.ExecuteStatus
    EXECUTE_STATUS_RUNNING: GTraceList.ExecuteStatus
    EXECUTE_STATUS_BLOCKED: GTraceList.ExecuteStatus
    EXECUTE_STATUS_FINISHED: GTraceList.ExecuteStatus
    LISTS_FIELD_NUMBER: _ClassVar[int]
    MAP_FIELD_NUMBER: _ClassVar[int]
    STATUS_FIELD_NUMBER: _ClassVar[int]
    lists: _containers.RepeatedCompositeFieldContainer[GTraceSeg]
    map: bytes
    status: GTraceList.ExecuteStatus
    def __init__(self, lists: _Optional[_Iterable[_Union[GTraceSeg, _Mapping]]] = ..., map: _Optional[bytes] = ..., status: _Optional[_Union[GTraceList.ExecuteStatus, str]] = ...) -> None: ...

class GLaserScan(_message.Message):
    __slots__ = ("stamp", "frame_id", "angle_min", "angle_max", "angle_increment", "time_increment", "scan_time", "range_min", "range_max", "ranges")
    STAMP_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    ANGLE_MIN_FIELD_NUMBER: _ClassVar[int]
    ANGLE_MAX_FIELD_NUMBER: _ClassVar[int]
    ANGLE_INCREMENT_FIELD_NUMBER: _ClassVar[int]
    TIME_INCREMENT_FIELD_NUMBER: _ClassVar[int]
    SCAN_TIME_FIELD_NUMBER: _ClassVar[int]
    RANGE_MIN_FIELD_NUMBER: _ClassVar[int]
    RANGE_MAX_FIELD_NUMBER: _ClassVar[int]
    RANGES_FIELD_NUMBER: _ClassVar[int]
    stamp: float
    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    time_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, stamp: _Optional[float] = ..., frame_id: _Optional[str] = ..., angle_min: _Optional[float] = ..., angle_max: _Optional[float] = ..., angle_increment: _Optional[float] = ..., time_increment: _Optional[float] = ..., scan_time: _Optional[float] = ..., range_min: _Optional[float] = ..., range_max: _Optional[float] = ..., ranges: _Optional[_Iterable[float]] = ...) -> None: ...

class RobotPose2D(_message.Message):
    __slots__ = ("stamp", "x", "y", "theta")
    STAMP_FIELD_NUMBER: _ClassVar[int]
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    THETA_FIELD_NUMBER: _ClassVar[int]
    stamp: float
    x: float
    y: float
    theta: float
    def __init__(self, stamp: _Optional[float] = ..., x: _Optional[float] = ..., y: _Optional[float] = ..., theta: _Optional[float] = ...) -> None: ...

class GRobotSpeedControl(_message.Message):
    __slots__ = ("linear", "angular", "stamp")
    LINEAR_FIELD_NUMBER: _ClassVar[int]
    ANGULAR_FIELD_NUMBER: _ClassVar[int]
    STAMP_FIELD_NUMBER: _ClassVar[int]
    linear: float
    angular: float
    stamp: float
    def __init__(self, linear: _Optional[float] = ..., angular: _Optional[float] = ..., stamp: _Optional[float] = ...) -> None: ...
