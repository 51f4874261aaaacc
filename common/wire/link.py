"""The Zenoh link between the master and the slave: one :class:`Link` per side.

A link owns a Zenoh session (use it as a context manager: the session is always closed), a
publisher for this side's messages (``<prefix>/handle`` from the master, ``<prefix>/tool`` from
the slave), a subscriber for the peer's with a ``RingChannel`` the control loop drains with
``try_recv()`` (no Python callback runs in Zenoh's threads, so nothing competes with the loop
for the GIL), and a liveliness token ``<prefix>/alive/<side>`` plus a liveliness subscriber on
the peer's token.

Timing: ``send_time_ns`` is ``CLOCK_REALTIME`` (:func:`time.time_ns`). On one host both
processes read the same clock; across hosts the clocks must be synchronised (PTP or chrony),
and the error between them adds directly to the measured and injected one-way delay. The
arrival time of a sample is Zenoh's own receive timestamp (timestamp-stack instrumentation,
taken in the Zenoh runtime when the sample arrives, on the same clock), so the measured delay
does not include the wait for the loop's next poll; without it the poll time is used.

Pairing (common/wire/auth.py): each side publishes a hello on ``<prefix>/pair/<side>`` that
names the lane law it runs (:attr:`Link.hello_control`; None, a 7-field hello: the programs'
own messages, ``[control] mode`` "paper" or "tdpa"). A peer's hello of another schema
version, with authentication on one side only, or naming another control is never paired on:
it sets :attr:`Link.peer_mismatch`, and :meth:`Link.wait_for_peer` raises
:class:`~haptic.common.wire.errors.LinkOpenError` with that line once such a peer has been seen
for :data:`MISMATCH_GRACE_S` without a pairing, so a master and a slave of different control
families refuse to start instead of dropping each other's messages as ``wrong_kind``.

Injection, ordering and the counters live in :class:`haptic.common.wire.receive.ReceivePath`.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import zenoh

from haptic.common.config import ConfigError
from haptic.common.wire.auth import (
    HELLO_PERIOD_S,
    NONCE_BYTES,
    Hello,
    HelloError,
    SessionAuth,
    decode_hello,
    encode_hello,
)
from haptic.common.wire.errors import LinkOpenError, one_line
from haptic.common.wire.link_config import LinkConfig
from haptic.common.wire.messages import (
    KIND_HANDLE,
    KIND_TOOL,
    SCHEMA_VERSION,
    DropReason,
    Flags,
    HandleState,
    Message,
    ToolState,
    encode_around_send_time,
    encode_handle_around_send_time,
    encode_tool_around_send_time,
    send_time_bytes,
)
from haptic.common.wire.protected_mode import Protection, require_protection
from haptic.common.wire.receive import LinkStats, ReceivePath
from haptic.common.wire.transport_auth import open_session

NO_FLAGS = Flags(0)
#: A mismatched peer (another schema version, authentication on one side, another control)
#: seen this long without a pairing stops the start, s.
MISMATCH_GRACE_S = 1.0
_CONGESTION = {"drop": zenoh.CongestionControl.DROP, "block": zenoh.CongestionControl.BLOCK}


def _receive_instrumentation() -> object | None:
    """Ask Zenoh to stamp each sample's arrival time (an unstable API; absent -> None)."""
    try:
        return zenoh.TimestampInstrumentationBuilder().set_receive(True).build()
    except Exception:  # noqa: BLE001 - older zenoh without timestamp stacks
        return None


_RECEIVE_POINT = getattr(getattr(zenoh, "InterceptionPoint", None), "RECEIVE", None)


def _mode_text(control: str | None) -> str:
    """A hello's control as the ``[control] mode`` values it stands for, quoted."""
    return '"paper" or "tdpa"' if control is None else f'"{control}"'


def zenoh_config(config: LinkConfig) -> zenoh.Config:
    """The Zenoh configuration of ``config``: the file first, the link's settings on top, the
    ``zenoh_overrides`` last."""
    if config.zenoh_config_file:
        zconf = zenoh.Config.from_file(config.zenoh_config_file)
    else:
        zconf = zenoh.Config()
    for key, value in config.zenoh_settings():
        zconf.insert_json5(key, value)
    return zconf


@dataclass(frozen=True)
class PresenceEvent:
    """The peer's liveliness token appeared (``alive``) or went away, at ``time_ns``
    (CLOCK_REALTIME)."""

    time_ns: int
    alive: bool

    def as_dict(self) -> dict[str, object]:
        """For the run summary's ``events`` (``time_s`` on CLOCK_REALTIME, s)."""
        kind = "peer_alive" if self.alive else "peer_gone"
        return {"time_s": self.time_ns * 1e-9, "kind": kind, "reason": "liveliness token"}


class Link:
    """One side's end of the link. Not thread-safe: call it from the control loop only.

    ``rng`` drives the injected jitter and loss (default: seeded from ``config.seed``);
    ``clock_ns`` is the send-time clock (CLOCK_REALTIME); ``epoch`` identifies this run of the
    sender (default: random).
    """

    hello_control: str | None = None
    """The lane law this side's hellos announce and its peer's must announce too (None: the
    programs' own messages; :class:`~haptic.common.wire.law_link.LawLink` sets its control)."""

    def __init__(
        self,
        config: LinkConfig,
        rng: np.random.Generator | None = None,
        clock_ns: Callable[[], int] = time.time_ns,
        epoch: int | None = None,
    ) -> None:
        self.config = config
        if rng is None:
            rng = np.random.default_rng(config.seed)
        self._clock_ns = clock_ns
        self.epoch = int(np.random.default_rng().integers(0, 2**32)) if epoch is None else epoch
        self._seq = 0
        self._send_kind = KIND_HANDLE if config.side == "master" else KIND_TOOL
        self.receive = ReceivePath(
            KIND_TOOL if config.side == "master" else KIND_HANDLE,
            config.injection,
            rng,
            config.stale_after_s,
        )
        self._instrumentation = _receive_instrumentation()
        self._session: zenoh.Session | None = None
        self._publisher: zenoh.Publisher | None = None
        self._subscriber: zenoh.Subscriber | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._presence: zenoh.Subscriber | None = None
        #: the peer's token going away, held while a capped poll left samples in the ring
        self._presence_held: zenoh.Sample | None = None
        self.peer_alive = False
        self.presence_events: list[PresenceEvent] = []
        self.last_poll_ns = 0
        """Time of the latest :meth:`poll` on the link's clock, ns."""
        self.sent = 0
        self.send_errors = 0
        self.first_sent_ns = 0
        self.last_sent_ns = 0
        """Send times of the first and the newest message this link sent, ns (0: none yet):
        what an echo of this side's send time can be (common/wire/messages.py ToolState)."""
        self.capped_polls = 0
        """Polls that took ``max_samples_per_poll`` samples and left the rest for the next."""
        self.discarded_before_start = 0
        """Samples :meth:`discard_received` dropped undecoded (before this side's first tick)."""
        # pairing (common/wire/auth.py): hellos on <prefix>/pair/<side>, tags with a session key
        self._psk = config.session_key
        self.auth = SessionAuth(self._psk, config.side, self.epoch) if self._psk else None
        self._nonce = self.auth.nonce if self.auth else secrets.token_bytes(NONCE_BYTES)
        self._hello_publisher: zenoh.Publisher | None = None
        self._hello_subscriber: zenoh.Subscriber | None = None
        self._next_hello_ns = 0
        self.undecodable_hellos = 0
        """Hellos on the peer's pairing key that did not decode (or whose tag did not verify),
        with or without a session key; the summary's ``link_rejected_hellos`` adds the ones
        the pairing refused."""
        self.peer_hello: Hello | None = None
        """The peer's latest valid hello (its run's epoch; None before the first)."""
        self.peer_mismatch: str | None = None
        """Why the peer cannot be paired with (another schema version, authentication on one
        side only, another control), or None: one line."""
        self.unpaired_sends = 0
        self._mismatch_since: float | None = None
        """Messages not sent because this authenticated side was not paired yet."""
        self.protection: Protection | None = None
        """The protected mode's verdict on the open session (None before :meth:`open`)."""

    # -- lifecycle ---------------------------------------------------------------------------

    def open(self) -> Link:
        """Open the session and declare the publisher, subscribers and liveliness token.
        Raises :class:`~haptic.common.runtime.failures.LinkOpenError` (one line) when Zenoh cannot
        open the session, or, before anything opens, when the protected mode refuses it (the
        programs check that earlier, as a configuration error: common/wire/protected_mode.py)."""
        if self._session is not None:
            return self
        c = self.config
        zconf = zenoh_config(c)
        try:
            self.protection = require_protection(zconf, c.session_key is not None, c.insecure)
        except ConfigError as error:
            raise LinkOpenError(str(error)) from None
        try:
            self._session = open_session(zconf, c.transport_key)
        except zenoh.ZError as error:  # a port in use, an unreachable router, a bad file
            raise LinkOpenError(
                f"cannot open the Zenoh session (mode {c.mode}, listen "
                f"{(c.mode != 'client' and ','.join(c.listen)) or '-'}, connect "
                f"{','.join(c.connect) or '-'}): "
                f"{one_line(error)}") from None
        try:
            self._publisher = self._session.declare_publisher(
                c.publish_key,
                congestion_control=_CONGESTION[c.congestion_control],
                priority=zenoh.Priority.REAL_TIME,
                express=c.express,
            )
            self._subscriber = self._session.declare_subscriber(
                c.subscribe_key, zenoh.handlers.RingChannel(c.receive_queue_capacity)
            )
            liveliness = self._session.liveliness()
            self._presence = liveliness.declare_subscriber(
                c.liveliness_key(c.peer_side), zenoh.handlers.FifoChannel(64), history=True
            )
            self._token = liveliness.declare_token(c.liveliness_key(c.side))
            self._hello_publisher = self._session.declare_publisher(
                c.key(f"pair/{c.side}"), congestion_control=zenoh.CongestionControl.BLOCK)
            self._hello_subscriber = self._session.declare_subscriber(
                c.key(f"pair/{c.peer_side}"), zenoh.handlers.FifoChannel(16))
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Undeclare everything and close the session (idempotent)."""
        session, self._session = self._session, None
        for name in ("_token", "_presence", "_subscriber", "_publisher", "_hello_subscriber",
                     "_hello_publisher"):
            entity = getattr(self, name)
            setattr(self, name, None)
            if entity is not None and session is not None:
                try:
                    entity.undeclare()
                except Exception:  # noqa: BLE001 - best effort while closing
                    pass
        if session is not None:
            session.close()

    def __enter__(self) -> Link:
        return self.open()

    def __exit__(self, *_exc: object) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        return self._session is not None

    @property
    def session(self) -> zenoh.Session | None:
        """The open Zenoh session (for display-rate publications off the loop), or None."""
        return self._session

    # -- sending -----------------------------------------------------------------------------

    def next_sequence(self) -> int:
        """The sequence number of the next message (consumes it)."""
        seq = self._seq
        self._seq = seq + 1
        return seq

    def send(self, message: Message) -> Message:
        """Stamp ``message`` with the send time (its own ``send_time_ns`` is ignored) and
        publish it; returns it as sent. The time is taken after the encoding, right before
        the put, so the measured one-way delay is the link's, not the encoder's. A Zenoh
        error is counted in ``send_errors``, not raised: the loop must keep its period. Raises
        ``ValueError`` for a non-finite value (the nodes never send one)."""
        self._check_kind(message.KIND)
        return replace(message, send_time_ns=self._publish(*encode_around_send_time(message)))

    def _check_kind(self, kind: int) -> None:
        if kind != self._send_kind:
            raise TypeError(f"the {self.config.side} side sends kind {self._send_kind} only")

    def _publish(self, before: bytes, after: bytes) -> int:
        """Put the message encoded around its send time (:meth:`send`); returns that time,
        ns (``CLOCK_REALTIME``)."""
        publisher = self._publisher
        if publisher is None:
            raise RuntimeError("link is not open")
        send_ns = self._clock_ns()
        payload = before + send_time_bytes(send_ns) + after
        auth = self.auth
        if auth is not None:
            if not auth.paired:  # nothing leaves before the pairing: the peer would drop it
                self.unpaired_sends += 1
                return send_ns
            payload += auth.tag(payload)
        try:
            if self._instrumentation is not None:
                publisher.put(payload, timestamp_instrumentation=self._instrumentation)
            else:
                publisher.put(payload)
            self.sent += 1
            self.last_sent_ns = send_ns
            if not self.first_sent_ns:
                self.first_sent_ns = send_ns
        except Exception:  # noqa: BLE001 - a failed put is a lost message, never a crash
            self.send_errors += 1
        return send_ns

    def send_handle(
        self,
        handle_force_N: tuple[float, float],
        handle_position_m: tuple[float, float],
        flags: Flags = NO_FLAGS,
        gain_k: float = 0.0,
        energy_J: float = 0.0,
        force_scale: float = 1.0,
    ) -> HandleState:
        """Master: stamp and publish the handle's force (N), position (m), the Ch1 gain k
        its compensator uses (0: not said), the passivity layer's handed-over energy (J) and
        the force ramp's factor at this sample (0..1); returns the message as sent (as
        :meth:`send`, encoded from the fields without building it first)."""
        self._check_kind(KIND_HANDLE)
        epoch, seq = self.epoch, self.next_sequence()
        send_ns = self._publish(*encode_handle_around_send_time(
            epoch, seq, flags, handle_force_N, handle_position_m, gain_k, energy_J,
            force_scale))
        return HandleState(epoch, seq, send_ns, flags, handle_force_N, handle_position_m,
                           gain_k, energy_J, force_scale)

    def send_tool(
        self,
        tool_force_N: tuple[float, float],
        tool_position_m: tuple[float, float],
        tool_velocity_m_s: tuple[float, float],
        clay_engagement: float,
        removed_volume_m3: float,
        flags: Flags = NO_FLAGS,
        echo_send_time_ns: int = 0,
        energy_J: float = 0.0,
    ) -> ToolState:
        """Slave: stamp and publish the tool's force (N), position (m), velocity (m/s), the
        clay's status, the echo of the newest handle message's send time (ns; 0: none) and
        the passivity layer's handed-over energy (J); returns the message as sent."""
        self._check_kind(KIND_TOOL)
        epoch, seq = self.epoch, self.next_sequence()
        send_ns = self._publish(*encode_tool_around_send_time(
            epoch, seq, flags, tool_force_N, tool_position_m, tool_velocity_m_s,
            clay_engagement, removed_volume_m3, echo_send_time_ns, energy_J))
        return ToolState(epoch, seq, send_ns, flags, tool_force_N, tool_position_m,
                         tool_velocity_m_s, clay_engagement, removed_volume_m3,
                         echo_send_time_ns, energy_J)

    # -- receiving ---------------------------------------------------------------------------

    def _arrival_ns(self, sample: zenoh.Sample, now_ns: int) -> int:
        if _RECEIVE_POINT is None:
            return now_ns
        stack = sample.timestamp_stack
        if stack is None:
            return now_ns
        for record in stack.records:
            if record.point == _RECEIVE_POINT and not record.is_custom:
                return record.timestamp().get_time_as_ntp64().as_nanos()
        return now_ns

    def poll(self, now_ns: int | None = None) -> Message | None:
        """Drain what was received since the last poll (at most ``max_samples_per_poll``
        samples: the rest wait for the next poll; ``capped_polls`` counts polls that reached
        the bound) into the receive path and return the newest message whose delivery time has
        come (``None`` if none). Also updates ``peer_alive`` from the liveliness subscriber:
        its going away waits while received samples are left in the ring (a capped poll), so
        what the peer sent before it left, its last message included, is taken first (a
        killed peer's silence trips the watchdog meanwhile). Never blocks."""
        subscriber = self._subscriber
        if subscriber is None:
            raise RuntimeError("link is not open")
        if now_ns is None:
            now_ns = self._clock_ns()
        self.last_poll_ns = now_ns
        receive = self.receive
        budget = self.config.max_samples_per_poll  # flood bound: the rest wait in the ring
        sample = subscriber.try_recv()
        auth = self.auth
        capped = False
        while sample is not None:
            payload = sample.payload.to_bytes()
            if receive.rejects_at_once(payload):  # junk costs no stamp, no decode
                pass
            elif auth is None:
                receive.accept(payload, self._arrival_ns(sample, now_ns))
            elif (body := auth.verify(payload)) is not None:
                receive.accept(body, self._arrival_ns(sample, now_ns))
            else:
                receive.drop(DropReason.UNAUTHENTICATED if auth.paired
                             else DropReason.UNPAIRED)
            budget -= 1
            if budget == 0:
                self.capped_polls += 1
                capped = True
                break
            sample = subscriber.try_recv()
        self._pair(now_ns)
        presence = self._presence
        if presence is not None:
            change = self._presence_held
            self._presence_held = None
            if change is None:
                change = presence.try_recv()
            while change is not None:
                alive = change.kind == zenoh.SampleKind.PUT
                if not alive and capped and self.peer_alive:
                    self._presence_held = change  # the samples before it first
                    break
                if alive != self.peer_alive:
                    self.peer_alive = alive
                    self.presence_events.append(PresenceEvent(now_ns, alive))
                    if alive:
                        self._next_hello_ns = 0  # its session is there: pair without waiting
                change = presence.try_recv()
        return receive.release(now_ns)

    def discard_received(self) -> int:
        """Drop what the receive ring holds now, undecoded, and return how many samples
        (``discarded_before_start``). For the moment before a loop's first tick: what the
        peer sent while this side started up (its loop may run for a second before this one)
        is older than any tick can use, and its decoding and tags in the first polls
        (``max_samples_per_poll`` each) took 0.4-0.9 ms a tick for the master's first six
        ticks in ``haptic-session``: start-up stalls. The peer's presence and its hellos stay
        in their channels; the newest message comes again within a period."""
        subscriber = self._subscriber
        if subscriber is None:
            raise RuntimeError("link is not open")
        count = 0
        while subscriber.try_recv() is not None:
            count += 1
        self.discarded_before_start += count
        return count

    def _pair(self, now_ns: int) -> None:
        """Take the peer's hellos (at most 8 per poll), pair on a new one (authenticated, with
        a key) that matches this side (:meth:`_mismatch_of`; a mismatched one only sets
        :attr:`peer_mismatch`), and publish this side's hello, with :attr:`hello_control`,
        every HELLO_PERIOD_S (at once after a new pairing)."""
        subscriber = self._hello_subscriber
        if subscriber is None:
            return
        auth = self.auth
        for _ in range(8):
            sample = subscriber.try_recv()
            if sample is None:
                break
            try:
                hello = decode_hello(sample.payload.to_bytes(), self._psk)
            except HelloError:
                self.undecodable_hellos += 1
                continue
            mismatch = self._mismatch_of(hello)
            if mismatch is not None:
                self.peer_mismatch = mismatch
                continue
            if auth is None:
                if hello.side == self.config.peer_side:
                    known = self.peer_hello
                    if known is None or (known.epoch, known.nonce) != (hello.epoch, hello.nonce):
                        self._next_hello_ns = 0  # a new peer run: answer at once
                    self.peer_hello = hello
            elif auth.accept_hello(hello, now_ns):
                self.peer_hello = hello
                self.receive.pin_epoch(hello.epoch)
                self._next_hello_ns = 0  # answer at once, so the peer pairs too
        publisher = self._hello_publisher
        if publisher is not None and now_ns >= self._next_hello_ns:
            self._next_hello_ns = now_ns + int(HELLO_PERIOD_S * 1e9)
            control = self.hello_control
            payload = (auth.hello(now_ns, control) if auth is not None else
                       encode_hello(self.config.side, self.epoch, self._nonce, now_ns, None,
                                    control))
            try:
                publisher.put(payload)
            except Exception:  # noqa: BLE001 - a lost hello is sent again
                self.send_errors += 1

    def _mismatch_of(self, hello: Hello) -> str | None:
        """Why this decoded hello cannot pair (one line), or None: another schema version,
        authentication on one side only, or, from the peer's side, another control than
        :attr:`hello_control`."""
        peer = self.config.peer_side
        if hello.version != SCHEMA_VERSION:
            return (f"the {peer} speaks wire schema version {hello.version}, "
                    f"this program {SCHEMA_VERSION}: run the same haptic-teleop on both sides")
        authenticated = self.auth is not None
        if hello.authenticated != authenticated:
            return (f"the {peer} "
                    f"{'authenticates' if hello.authenticated else 'does not authenticate'} "
                    f"its messages and this side {'does' if authenticated else 'does not'}: "
                    "give both sides the same [link.security] session_key_file "
                    "(--session-key), or neither")
        if hello.side == peer and hello.control != self.hello_control:
            return (f"the {peer} runs [control] mode = {_mode_text(hello.control)}, this side "
                    f"{_mode_text(self.hello_control)}; set the same [control] mode on both "
                    "sides")
        return None

    @property
    def paired(self) -> bool:
        """The peer's hello came (and, authenticated, the session key is derived)."""
        if self.auth is not None:
            return self.auth.paired
        return self.peer_hello is not None

    def _check_peer(self) -> None:
        """Raise :class:`LinkOpenError` when, unpaired, a mismatched peer has been seen for
        :data:`MISMATCH_GRACE_S` (a stranger's single mismatched hello does not stop a start
        that pairs with the real peer meanwhile)."""
        version = self.receive.last_unknown_version
        if self.peer_mismatch is None and version is not None:
            self.peer_mismatch = (
                f"the {self.config.peer_side} speaks wire schema version {version}, this "
                f"program {SCHEMA_VERSION}: run the same haptic-teleop on both sides")
        if self.peer_mismatch is None or self.paired:
            self._mismatch_since = None
            return
        now = time.monotonic()
        if self._mismatch_since is None:
            self._mismatch_since = now
        if now - self._mismatch_since >= MISMATCH_GRACE_S:
            raise LinkOpenError(self.peer_mismatch)

    @property
    def last_delivery_ns(self) -> int | None:
        """When the newest delivered message came (``time.perf_counter_ns``; None before
        the first): what the slave's phase lock measures against its poll."""
        return self.receive.last_delivery_ns

    @property
    def last_delivery_measured(self) -> bool:
        """Whether the newest delivered message's delivery time is a measurement: Zenoh's
        arrival stamp or an injected delivery time. Without a stamp (a peer without timestamp
        instrumentation) the arrival is the draining poll's own time, which says nothing
        about when the message came."""
        delivery = self.receive.last_delivery_ns
        return delivery is not None and delivery != self.last_poll_ns

    def wait_for_peer(
        self,
        timeout_s: float | None,
        should_stop: Callable[[], bool] | None = None,
        poll_interval_s: float = 0.001,
    ) -> bool:
        """Poll until the peer's liveliness token is seen and the peer paired (its hello came
        and, authenticated, verified) (True), or ``timeout_s`` passes (``None``: no limit) or
        ``should_stop()`` says so (False). Messages that arrive meanwhile go through the
        receive path as usual. Raises :class:`LinkOpenError` for a peer that cannot be paired
        with (another wire schema version, authentication on one side only, another control:
        :attr:`peer_mismatch`)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not (self.peer_alive and self.paired):
            self._check_peer()
            if should_stop is not None and should_stop():
                return False
            if deadline is not None and time.monotonic() > deadline:
                return False
            self.poll()
            if not (self.peer_alive and self.paired):
                time.sleep(poll_interval_s)
        return True

    @property
    def delivered(self) -> list[Message]:
        """Every message the last :meth:`poll` delivered, in order, the newest (the one it
        returned) last; empty when it returned ``None``. Reused: read it before the next
        poll."""
        return self.receive.released

    @property
    def latest(self) -> Message | None:
        """The newest message delivered so far (``None`` before the first)."""
        return self.receive.last_delivered

    def silence_s(self, now_ns: int | None = None) -> float:
        """Time since the last fresh message was delivered, s (inf before the first): what the
        application watchdog compares with ``max_message_age_s``."""
        last = self.receive.last_delivery_ns
        if last is None:
            return float("inf")
        if now_ns is None:
            now_ns = self._clock_ns()
        return (now_ns - last) * 1e-9

    def message_age_s(self, now_ns: int | None = None) -> float:
        """Age of the newest delivered message (now minus its send time), s; inf before the
        first. Includes the injected delay."""
        latest = self.receive.last_delivered
        if latest is None:
            return float("inf")
        if now_ns is None:
            now_ns = self._clock_ns()
        return (now_ns - latest.send_time_ns) * 1e-9

    def stats(self) -> LinkStats:
        return self.receive.stats()

    def summary(self) -> dict[str, object]:
        """The link's keys of the run summary."""
        result = self.stats().as_summary()
        result["link_sent"] = self.sent
        result["link_send_errors"] = self.send_errors
        result["link_capped_polls"] = self.capped_polls
        result["link_discarded_before_start"] = self.discarded_before_start
        result["link_authenticated"] = self.auth is not None
        result["link_pairings"] = self.auth.pairings if self.auth is not None else None
        result["link_rejected_hellos"] = self.undecodable_hellos + (
            self.auth.rejected_hellos if self.auth is not None else 0)
        result["link_unpaired_sends"] = self.unpaired_sends
        result["link_peer_alive"] = self.peer_alive
        if self.protection is not None:
            result.update(self.protection.summary())
        return result
