"""A minimal CDR reader written from the OMG CDR rules (XCDR1, as ROS 2 uses), independent
of the serializer under test: the 4-byte encapsulation header (byte 1 says the byte order),
then each primitive aligned to its own size counted from the end of the header; a string is
a uint32 length (with its NUL) and the bytes; a sequence a uint32 count and the elements."""

from __future__ import annotations

import struct


class CdrReader:
    """Reads fields in order from one CDR payload."""

    def __init__(self, payload: bytes) -> None:
        if len(payload) < 4 or payload[0] != 0 or payload[1] not in (0, 1):
            raise ValueError(f"not a plain CDR encapsulation: {payload[:4].hex()}")
        self.order = "<" if payload[1] == 1 else ">"
        self.data = payload[4:]
        self.pos = 0

    def _read(self, code: str, size: int) -> float | int:
        self.pos += (-self.pos) % size
        (value,) = struct.unpack_from(self.order + code, self.data, self.pos)
        self.pos += size
        return value

    def u8(self) -> int:
        return int(self._read("B", 1))

    def u32(self) -> int:
        return int(self._read("I", 4))

    def i32(self) -> int:
        return int(self._read("i", 4))

    def f64(self) -> float:
        return float(self._read("d", 8))

    def boolean(self) -> bool:
        return bool(self.u8())

    def string(self) -> str:
        length = self.u32()
        text = self.data[self.pos:self.pos + length]
        self.pos += length
        if not text.endswith(b"\0"):
            raise ValueError("a CDR string ends with NUL")
        return text[:-1].decode()

    def octets(self) -> bytes:
        count = self.u32()
        value = self.data[self.pos:self.pos + count]
        self.pos += count
        return bytes(value)

    def f64_sequence(self) -> list[float]:
        return [self.f64() for _ in range(self.u32())]

    def at_end(self) -> bool:
        """Nothing but padding (< 4 bytes) left."""
        return len(self.data) - self.pos < 4

    # ROS 2 structures the tests check
    def header(self) -> tuple[int, int, str]:
        """std_msgs/Header: (sec, nanosec, frame_id)."""
        return self.i32(), self.u32(), self.string()

    def vector3(self) -> tuple[float, float, float]:
        return self.f64(), self.f64(), self.f64()

    def quaternion(self) -> tuple[float, float, float, float]:
        return self.f64(), self.f64(), self.f64(), self.f64()


def read_wrench(payload: bytes) -> dict:
    r = CdrReader(payload)
    result = {"header": r.header(), "force": r.vector3(), "torque": r.vector3()}
    assert r.at_end()
    return result


def read_pose(payload: bytes) -> dict:
    r = CdrReader(payload)
    result = {"header": r.header(), "position": r.vector3(), "orientation": r.quaternion()}
    assert r.at_end()
    return result


def read_joint_state(payload: bytes) -> dict:
    r = CdrReader(payload)
    header = r.header()
    names = [r.string() for _ in range(r.u32())]
    result = {"header": header, "name": names, "position": r.f64_sequence(),
              "velocity": r.f64_sequence(), "effort": r.f64_sequence()}
    assert r.at_end()
    return result


def read_tf(payload: bytes) -> list[dict]:
    r = CdrReader(payload)
    transforms = []
    for _ in range(r.u32()):
        transforms.append({"header": r.header(), "child": r.string(),
                           "translation": r.vector3(), "rotation": r.quaternion()})
    assert r.at_end()
    return transforms


def read_diagnostics(payload: bytes) -> dict:
    r = CdrReader(payload)
    header = r.header()
    statuses = []
    for _ in range(r.u32()):
        level, name, message, hardware_id = r.u8(), r.string(), r.string(), r.string()
        values = {}
        for _ in range(r.u32()):
            key = r.string()
            values[key] = r.string()
        statuses.append({"level": level, "name": name, "message": message,
                         "hardware_id": hardware_id, "values": values})
    assert r.at_end()
    return {"header": header, "status": statuses}


def read_point_cloud(payload: bytes) -> dict:
    r = CdrReader(payload)
    header = r.header()
    height, width = r.u32(), r.u32()
    fields = []
    for _ in range(r.u32()):
        fields.append((r.string(), r.u32(), r.u8(), r.u32()))  # name, offset, datatype, count
    big, point_step, row_step = r.boolean(), r.u32(), r.u32()
    data = r.octets()
    dense = r.boolean()
    assert r.at_end()
    return {"header": header, "height": height, "width": width, "fields": fields,
            "is_bigendian": big, "point_step": point_step, "row_step": row_step,
            "data": data, "is_dense": dense}


def read_twist(payload: bytes) -> dict:
    r = CdrReader(payload)
    result = {"header": r.header(), "linear": r.vector3(), "angular": r.vector3()}
    assert r.at_end()
    return result
