"""The in-memory trace of a run."""

from __future__ import annotations

import numpy as np

from haptic.common.records.trace import TraceRecorder


def test_every_nth_sample_is_kept_and_saved(tmp_path) -> None:
    trace = TraceRecorder(("time_s", "force_N"), every=3, capacity=4)
    for i in range(20):
        if trace.due():
            trace.record((i * 0.1, float(i)))
        else:
            trace.skip()
    data = trace.arrays()
    assert data["force_N"].tolist() == [0.0, 3.0, 6.0, 9.0]
    assert trace.dropped == 3  # 12, 15, 18 found the array full
    path = trace.save(tmp_path / "sub" / "trace.npz")
    loaded = np.load(path)
    assert loaded["time_s"].tolist() == data["time_s"].tolist() and int(loaded["every"]) == 3
