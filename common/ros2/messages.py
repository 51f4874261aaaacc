"""The teleoperation's figures as standard ROS 2 messages, serialized to CDR by rosbags (its
Jazzy type store; the RIHS01 hashes of these types are the same in Jazzy, Kilted and
Rolling).

Each builder takes plain numbers (SI units: N, m, m/s) and a CLOCK_REALTIME stamp in ns and
returns a rosbags message object; :func:`serialize` makes its CDR bytes (with the 4-byte
encapsulation header). Positions are the x-y plane of the handle or the tool, z = 0; the
clay's heights are z.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

#: The frame the poses, /tf and the clay's points are given in.
WORLD_FRAME = "world"

WRENCH = "geometry_msgs/msg/WrenchStamped"
POSE = "geometry_msgs/msg/PoseStamped"
JOINT_STATE = "sensor_msgs/msg/JointState"
TF = "tf2_msgs/msg/TFMessage"
DIAGNOSTICS = "diagnostic_msgs/msg/DiagnosticArray"
POINT_CLOUD = "sensor_msgs/msg/PointCloud2"
TWIST = "geometry_msgs/msg/TwistStamped"


@functools.cache
def typestore() -> Any:
    """rosbags' Jazzy type store (loaded once, on first use: a fraction of a second)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def type_hash(type_name: str) -> str:
    """The type's ``RIHS01_<64 hex>`` hash (REP-2011)."""
    return typestore().hash_rihs01(type_name)


def serialize(message: Any, type_name: str) -> bytes:
    """Little-endian CDR with its encapsulation header."""
    return bytes(typestore().serialize_cdr(message, type_name))


def deserialize(data: bytes, type_name: str) -> Any:
    """The inverse of :func:`serialize`."""
    return typestore().deserialize_cdr(data, type_name)


def _t(name: str) -> Any:
    return typestore().types[name]


def header(stamp_ns: int, frame_id: str) -> Any:
    """std_msgs/Header at ``stamp_ns`` (CLOCK_REALTIME ns)."""
    stamp = _t("builtin_interfaces/msg/Time")(sec=stamp_ns // 1_000_000_000,
                                              nanosec=stamp_ns % 1_000_000_000)
    return _t("std_msgs/msg/Header")(stamp=stamp, frame_id=frame_id)


def _vector(x: float, y: float, z: float = 0.0) -> Any:
    return _t("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def wrench(stamp_ns: int, frame_id: str, force_N: Sequence[float]) -> Any:
    """WrenchStamped: the x-y force, N (no torque)."""
    return _t(WRENCH)(header=header(stamp_ns, frame_id), wrench=_t("geometry_msgs/msg/Wrench")(
        force=_vector(force_N[0], force_N[1]), torque=_vector(0.0, 0.0)))


def _pose(position_m: Sequence[float]) -> Any:
    point = _t("geometry_msgs/msg/Point")(x=float(position_m[0]), y=float(position_m[1]),
                                          z=0.0)
    identity = _t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0)
    return _t("geometry_msgs/msg/Pose")(position=point, orientation=identity)


def pose(stamp_ns: int, position_m: Sequence[float]) -> Any:
    """PoseStamped in :data:`WORLD_FRAME`: the x-y position, m; no rotation."""
    return _t(POSE)(header=header(stamp_ns, WORLD_FRAME), pose=_pose(position_m))


def joint_state(stamp_ns: int, names: Sequence[str], position_m: Sequence[float],
                velocity_m_s: Sequence[float], effort_N: Sequence[float]) -> Any:
    """JointState of prismatic axes: positions m, velocities m/s, efforts N."""
    return _t(JOINT_STATE)(
        header=header(stamp_ns, ""), name=list(names),
        position=np.asarray(position_m, dtype=np.float64),
        velocity=np.asarray(velocity_m_s, dtype=np.float64),
        effort=np.asarray(effort_N, dtype=np.float64))


def tf(stamp_ns: int, frames: Mapping[str, Sequence[float]]) -> Any:
    """TFMessage: each child frame at its x-y position in :data:`WORLD_FRAME`, m."""
    transforms = [
        _t("geometry_msgs/msg/TransformStamped")(
            header=header(stamp_ns, WORLD_FRAME), child_frame_id=child,
            transform=_t("geometry_msgs/msg/Transform")(
                translation=_vector(position[0], position[1]),
                rotation=_t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0)))
        for child, position in frames.items()]
    return _t(TF)(transforms=transforms)


def _text(value: Any) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}"
    return str(value)


def diagnostics(stamp_ns: int, name: str, hardware_id: str, level: int, summary: str,
                values: Mapping[str, Any]) -> Any:
    """DiagnosticArray with one status: ``level`` 0 OK, 1 WARN, 2 ERROR, 3 STALE;
    ``values`` as key/value text (floats to 6 significant digits)."""
    key_value = _t("diagnostic_msgs/msg/KeyValue")
    status = _t("diagnostic_msgs/msg/DiagnosticStatus")(
        level=int(level), name=name, message=summary, hardware_id=hardware_id,
        values=[key_value(key=str(key), value=_text(value)) for key, value in values.items()])
    return _t(DIAGNOSTICS)(header=header(stamp_ns, ""), status=[status])


def point_cloud(stamp_ns: int, points_m: np.ndarray) -> Any:
    """PointCloud2 of ``points_m`` ((n, 3) x, y, z in m) as float32 x, y, z in
    :data:`WORLD_FRAME`, one row."""
    field = _t("sensor_msgs/msg/PointField")
    points = np.ascontiguousarray(points_m, dtype="<f4").reshape(-1, 3)
    fields = [field(name=axis, offset=4 * index, datatype=field.FLOAT32, count=1)
              for index, axis in enumerate("xyz")]
    return _t(POINT_CLOUD)(
        header=header(stamp_ns, WORLD_FRAME), height=1, width=int(points.shape[0]),
        fields=fields, is_bigendian=False, point_step=12, row_step=12 * int(points.shape[0]),
        data=np.frombuffer(points.tobytes(), dtype=np.uint8), is_dense=True)


def height_points(heights_m: np.ndarray, x_range_m: Sequence[float],
                  y_range_m: Sequence[float]) -> np.ndarray:
    """(n, 3) points of a (cells_y, cells_x) height map at its cells' centres over the
    ranges, m; cells without clay (height <= 0 or not finite) are left out."""
    cells_y, cells_x = heights_m.shape
    xs = x_range_m[0] + (np.arange(cells_x) + 0.5) * (x_range_m[1] - x_range_m[0]) / cells_x
    ys = y_range_m[0] + (np.arange(cells_y) + 0.5) * (y_range_m[1] - y_range_m[0]) / cells_y
    grid_x, grid_y = np.meshgrid(xs, ys)
    keep = np.isfinite(heights_m) & (heights_m > 0.0)
    return np.column_stack((grid_x[keep], grid_y[keep], heights_m[keep]))


def twist(stamp_ns: int, frame_id: str, velocity_m_s: Sequence[float]) -> Any:
    """TwistStamped: the x-y linear velocity, m/s (no rotation)."""
    return _t(TWIST)(header=header(stamp_ns, frame_id), twist=_t("geometry_msgs/msg/Twist")(
        linear=_vector(velocity_m_s[0], velocity_m_s[1]), angular=_vector(0.0, 0.0)))
