"""The force sensor's frames as the cycle's force: decoded
(:mod:`haptic.master.hardware.force_sensor`), checked (status, counter continuity, finite
newtons) and converted, with a fault where a frame is not a valid sample.
"""

from __future__ import annotations

import math

from haptic.master.hardware.force_sensor import STATUS_OK, ForceSensorCodec


class ForceSensorReader:
    """The force (N, x and y) of each sensor frame, and the faults of the frames that are not
    a valid sample."""

    def __init__(self, codec: ForceSensorCodec) -> None:
        self.codec = codec
        #: the last frame's counter (None: no frame yet)
        self.counter: int | None = None

    def force(self, data: bytes, faults: list[str]) -> tuple[float, float]:
        """The frame's force (N, x and y; both NaN where it is not a valid sample, with the
        fault: a status other than ok, or counts that scale beyond a float). A counter that is
        not the last one plus 1 is a fault too (a stale or lost sample), the force kept."""
        try:
            sample = self.codec.decode(data)
        except Exception as error:  # cantools raises several types for a bad frame
            faults.append(f"force sensor frame malformed: {error}")
            return math.nan, math.nan
        if self.counter is not None and sample.counter != (self.counter + 1) % 256:
            faults.append(f"force sensor counter jumped from {self.counter} to "
                          f"{sample.counter} (a stale or lost sample)")
        self.counter = sample.counter
        force = self.codec.newtons(sample)
        if math.isfinite(force[0]) and math.isfinite(force[1]):
            return force
        faults.append(f"force sensor status {sample.status} (not ok)" if sample.status
                      != STATUS_OK else f"force sensor counts ({sample.raw_x_count}, "
                      f"{sample.raw_y_count}) are not finite in N: see [master.can] "
                      "force_scale_N_per_count and force_offset_count")
        return math.nan, math.nan
