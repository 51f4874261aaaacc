"""The lockstep's two delay lines with their messages as named columns.

A line carries one message per lane and tick as a row of floats (lockstep/delay_line.py);
here each row's columns have names, so the simulator writes ``handle.force_N[...] = fh``
instead of ``row[:, 0:2] = fh``:

- the handle line (master -> slave): ``force_N`` (2, N: the force the master's Ch1 used),
  ``position_m`` (2, m), ``flags``, ``force_scale`` (0..1), then ``gain_ratio`` (k/k0, where
  governors run) and ``energy_J`` (the master's handed-over energy, J, in ``tdpa`` mode);
- the tool line (slave -> master): ``force_N`` (2, N), ``position_m`` (2, m),
  ``velocity_m_s`` (2, m/s), ``flags``, then ``energy_J`` (J, ``tdpa`` mode).

:class:`HandleLine` and :class:`ToolLine` also say what the receiving program's link would
say of each lane's newest message (fresh, silence, send tick and time, flags) and build the
message objects the supervisors take (``HandleState``, ``ToolState``) from a lane's row. Every
view is made once: the simulator's tick allocates nothing here.
"""

from __future__ import annotations

import numpy as np

from haptic.common.wire.messages import FLAGS_BY_VALUE, HandleState, ToolState
from haptic.lockstep.delay_line import DelayLine


class HandleMessages:
    """Named views of a (lanes, channels) array of handle messages (see the module)."""

    #: the columns a receiver reads (force, position, flags, force scale)
    MESSAGE_COLUMNS = 6
    FLAG_COLUMN = 4

    def __init__(self, rows: np.ndarray, governed: bool, tdpa: bool) -> None:
        self.rows = rows
        self.force_N = rows[:, 0:2]
        self.position_m = rows[:, 2:4]
        self.flags = rows[:, self.FLAG_COLUMN]
        self.force_scale = rows[:, 5]
        self.gain_ratio = rows[:, 6] if governed else None
        self.energy_J = rows[:, 6 + governed] if tdpa else None

    @staticmethod
    def channels(governed: bool, tdpa: bool) -> int:
        """The row's width with the optional columns."""
        return HandleMessages.MESSAGE_COLUMNS + int(governed) + int(tdpa)


class ToolMessages:
    """Named views of a (lanes, channels) array of tool messages (see the module)."""

    #: the columns a receiver reads (force, position, velocity, flags)
    MESSAGE_COLUMNS = 7
    FLAG_COLUMN = 6

    def __init__(self, rows: np.ndarray, tdpa: bool) -> None:
        self.rows = rows
        self.force_N = rows[:, 0:2]
        self.position_m = rows[:, 2:4]
        self.velocity_m_s = rows[:, 4:6]
        self.flags = rows[:, self.FLAG_COLUMN]
        self.energy_J = rows[:, 7] if tdpa else None

    @staticmethod
    def channels(tdpa: bool) -> int:
        """The row's width with the optional column."""
        return ToolMessages.MESSAGE_COLUMNS + int(tdpa)


class _Line:
    """A delay line whose rows are messages: the slot a tick's message is written into
    (:meth:`slot`), the newest one each lane may read (:meth:`receive`), and the arrival
    figures of the last receive, which the line updates in place: ``fresh``, ``silence_s``
    (s), ``send_time_ns``, ``flags`` (int) (lanes,) and ``columns`` (lanes, message
    columns + 1: the receiver's columns, then the send tick)."""

    def __init__(self, line: DelayLine, period_s: float, slots: list, received: object) -> None:
        self.line = line
        self.period_s = period_s
        self._slots = slots
        self._received = received
        self.fresh = line.fresh
        self.silence_s = line.silence_s
        self.send_time_ns = line.send_time_ns
        self.flags = line.flags
        self.columns = line.columns

    @property
    def schedule(self) -> np.ndarray:
        """The line's source schedule (steps, lanes)."""
        return self.line.schedule


class HandleLine(_Line):
    """The handle line (master -> slave) with :class:`HandleMessages` rows."""

    def __init__(self, line: DelayLine, period_s: float, governed: bool, tdpa: bool) -> None:
        super().__init__(line, period_s,
                         [HandleMessages(rows, governed, tdpa) for rows in line.buffer],
                         HandleMessages(line.rows, governed, tdpa))
        self.received: HandleMessages = self._received  # type: ignore[assignment]
        #: every message's sender epoch (the lockstep's master never restarts)
        self.epoch = np.zeros(line.rows.shape[0], np.int64)

    def slot(self, tick: int) -> HandleMessages:
        """The messages every lane sends at ``tick``, to write in place."""
        return self._slots[tick % self.line.history]

    def receive(self, tick: int) -> HandleMessages:
        """The newest message each lane may read at ``tick`` (ticks in order, from 0)."""
        self.line.receive(tick)
        return self.received

    def message(self, lane: int) -> HandleState:
        """``lane``'s newest message as the slave's guard and supervisor take it."""
        fx, fy, x, y, flags, scale, sent = self.columns[lane].tolist()
        return HandleState(0, int(sent), int(int(sent) * (self.period_s * 1e9)),
                           FLAGS_BY_VALUE[int(flags)], (fx, fy), (x, y), force_scale=scale)

    def messages(self) -> list[HandleState | None]:
        """The fresh message per lane (None where nothing new came)."""
        return [self.message(lane) if fresh else None
                for lane, fresh in enumerate(self.fresh.tolist())]


class ToolLine(_Line):
    """The tool line (slave -> master) with :class:`ToolMessages` rows."""

    def __init__(self, line: DelayLine, period_s: float, tdpa: bool) -> None:
        super().__init__(line, period_s, [ToolMessages(rows, tdpa) for rows in line.buffer],
                         ToolMessages(line.rows, tdpa))
        self.received: ToolMessages = self._received  # type: ignore[assignment]

    def slot(self, tick: int) -> ToolMessages:
        """The messages every lane sends at ``tick``, to write in place."""
        return self._slots[tick % self.line.history]

    def receive(self, tick: int) -> ToolMessages:
        """The newest message each lane may read at ``tick`` (ticks in order, from 0)."""
        self.line.receive(tick)
        return self.received

    def message_of(self, columns: np.ndarray) -> ToolState:
        """The ``ToolState`` of one lane's ``columns`` row (the receiver's columns, then the
        send tick), as the master's supervisor takes it."""
        fx, fy, x, y, vx, vy, flags, sent = columns.tolist()
        return ToolState(0, int(sent), int(int(sent) * (self.period_s * 1e9)),
                         FLAGS_BY_VALUE[int(flags)], (fx, fy), (x, y), (vx, vy), 0.0, 0.0)

    def message(self, lane: int) -> ToolState:
        """``lane``'s newest message."""
        return self.message_of(self.columns[lane])

    def messages(self) -> list[ToolState | None]:
        """The fresh message per lane (None where nothing new came)."""
        return [self.message(lane) if fresh else None
                for lane, fresh in enumerate(self.fresh.tolist())]


def handle_line(schedule: np.ndarray, initial: np.ndarray, period_s: float,
                runup_lag: np.ndarray, governed: bool, tdpa: bool) -> HandleLine:
    """The handle line over ``schedule`` (steps, lanes) holding ``initial`` (lanes,
    channels) before the first message arrives; ``runup_lag``: the run-up's messages were
    sent that many ticks before they are read (the line's delay)."""
    line = DelayLine(schedule, HandleMessages.channels(governed, tdpa), initial,
                     period_s=period_s, runup_lag=runup_lag,
                     message_columns=HandleMessages.MESSAGE_COLUMNS,
                     flag_column=HandleMessages.FLAG_COLUMN)
    return HandleLine(line, period_s, governed, tdpa)


def tool_line(schedule: np.ndarray, initial: np.ndarray, period_s: float,
              runup_lag: np.ndarray, tdpa: bool) -> ToolLine:
    """The tool line, as :func:`handle_line`."""
    line = DelayLine(schedule, ToolMessages.channels(tdpa), initial, period_s=period_s,
                     runup_lag=runup_lag, message_columns=ToolMessages.MESSAGE_COLUMNS,
                     flag_column=ToolMessages.FLAG_COLUMN)
    return ToolLine(line, period_s, tdpa)
