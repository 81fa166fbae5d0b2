"""The live flight control (DRC) session as a sans-I/O state machine: every decision about whether
devices may move, and nothing else.

Owns: the session's state and its transitions, the set-point every driven device must hold, the
``drone_control`` seq rules, the heartbeat, stick, emergency-stop, broker and authority failsafes, the
order of session changes (``drc_mode_enter`` / ``drc_mode_exit`` / losses / shutdown), and which
request gets which answer. Must not know: sockets, threads, MQTT, JSON, devices or clocks. Time
enters only as the ``at`` of each event; requests are opaque tokens handed back in :class:`Reply`.

Theory of operation (in the manner of h11's ``_state.py``)
------------------------------------------------------------
The caller feeds :meth:`DrcSession.handle` one event at a time and carries out the actions it
returns, in order. There are five states::

                 Enter                    LinkUp
        IDLE ──────────────▶ CONNECTING ──────────▶ ACTIVE ◀──────────┐
         ▲  ◀── LinkFailed ──┘                        │  │ heartbeat  │ Heartbeat,
         │                                 Exit,      │  │ lost,      │ Stick(seq 0),
         │                            BrokerLost,     │  ▼ EStop      │ Enter after EStop
         │  LinkClosed                idle timeout,   │ HOLDING ──────┘
         └──────────────── EXITING ◀─────────────────┴──┘ (same)

* **IDLE** (``drc_state`` 0): no session. Sticks and heartbeats are not answered (nobody listens).
* **CONNECTING** (1): the DRC broker link of one session is being opened (:class:`OpenLink`).
* **ACTIVE** (2): sticks drive the devices. A stick older than ``stick_timeout`` zeroes the set-point
  (a *stick* failsafe: the session goes on, the next stick drives again).
* **HOLDING** (2): a failsafe holds the zero set-point: an emergency stop (released by a stick whose
  seq restarts at 0, or by a fresh ``Enter`` of the same session) or heartbeats lost for
  ``heartbeat_timeout`` (released by the next heartbeat).
  Sticks are answered with an error, never with 0.
* **EXITING** (0): the set-point is zero, the session's link is being closed (:class:`CloseLink`);
  :class:`LinkClosed` returns to IDLE. The DRC state already reads 0: the session is over.

Session changes are serialised *here*: an ``Enter`` or ``Exit`` that arrives while a link is being
opened or closed waits in a FIFO queue and is handled when the link settles, so an exit always acts
on the session that was current when it arrived, and one session's link is closed before the next
one's is opened (at most one DRC link at any time). Every ``Enter`` and ``Exit`` is answered exactly
once (:class:`Reply`), queued ones included; ``Shutdown`` answers whatever is queued.

Payload commands (:class:`PayloadCommand`, ``drc_gimbal_reset``) move a device once: they are
forwarded (:class:`Forward`) only while no failsafe holds, and refused like sticks while one does.

Motion: :class:`Motion` carries the set-point every driven device must hold from now on (forward,
right, up m/s, yaw rate °/s) and whether it is streamed; the caller's single writer sends it. Any of
exit, emergency stop, heartbeat loss, stick loss, broker loss, authority loss or shutdown emits a
zero :class:`Motion` in the same call that observes it: the writer sends it at once, and the stream
keeps sending zero. :class:`EmergencyStop` additionally asks every device to brake now.
:attr:`DrcSession.setpoint` is the truth the invariants are checked against.

Clocks: :class:`Tick` events (the writer sends one per control period) apply the timeouts, so
stick and heartbeat losses are noticed within one control period of their deadline.

Why this module is longer than 500 lines: it is one state machine (states, events, actions and their
transition handlers) with its theory of operation; split, its invariants would span files.
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

__all__ = [
    "ZERO",
    "Action",
    "AuthorityLost",
    "BrokerLost",
    "CloseLink",
    "Count",
    "DrcSession",
    "EStop",
    "EmergencyStop",
    "Enter",
    "Event",
    "Exit",
    "Failsafe",
    "Forward",
    "Heartbeat",
    "LinkClosed",
    "LinkFailed",
    "LinkSpec",
    "LinkUp",
    "Motion",
    "Notify",
    "OpenLink",
    "PayloadCommand",
    "Reply",
    "Report",
    "SessionConfig",
    "Shutdown",
    "State",
    "Stick",
    "StickLimits",
    "StickReply",
    "Tick",
    "channels_to_setpoint",
]

SetPoint = tuple[float, float, float, float]  # forward, right, up (m/s), yaw rate (°/s, clockwise)
ZERO: SetPoint = (0.0, 0.0, 0.0, 0.0)

#: ``stick_control`` channel values (the same as schemas.drc's; plain ints so nothing of the contract
#: layer is imported): 1024 is neutral, 1024 ± 660 full deflection.
STICK_NEUTRAL, STICK_SPAN = 1024, 660


@dataclass(frozen=True, slots=True)
class StickLimits:
    """What a full ``stick_control`` deflection asks for (``drc.stick_*`` settings)."""

    horizontal: float = 10.0  # m/s forward (pitch) and right (roll)
    up: float = 5.0  # m/s at full throttle
    down: float = 4.0  # m/s at zero throttle
    yaw_rate: float = 90.0  # °/s clockwise at full yaw


def channels_to_setpoint(roll: int, pitch: int, throttle: int, yaw: int, limits: StickLimits) -> SetPoint:
    """RC channels (364..1684, 1024 neutral) → forward, right, up (m/s) and clockwise yaw rate (°/s),
    linear in each channel's deflection ``(value - 1024) / 660`` (DJI: roll larger = right, pitch larger
    = forward, throttle larger = up, yaw larger = clockwise); 1024 on every channel is ZERO (hover)."""
    up = (throttle - STICK_NEUTRAL) / STICK_SPAN
    return (
        (pitch - STICK_NEUTRAL) / STICK_SPAN * limits.horizontal,
        (roll - STICK_NEUTRAL) / STICK_SPAN * limits.horizontal,
        up * (limits.up if up > 0 else limits.down),
        (yaw - STICK_NEUTRAL) / STICK_SPAN * limits.yaw_rate,
    )


# Cloud API result codes used here (the same values as schemas.ResultCode; kept as plain ints so this
# module imports nothing of the contract layer).
SUCCESS = 0
BUSY = 314000
NO_FLIGHT_AUTHORITY = 319030
DRC_SEQ_TOO_OLD = 319033
DRC_HEARTBEAT_TIMEOUT = 514301
DRC_LINK_LOST = 514303

#: why a stick (or payload command) is refused while an emergency stop holds, and how to release it
_ESTOP_HOLDS = "emergency stop holds until a stick with seq 0 or a fresh drc_mode_enter"


class State(enum.Enum):
    IDLE = "idle"
    CONNECTING = "connecting"
    ACTIVE = "active"
    HOLDING = "holding"
    EXITING = "exiting"


#: The ``drc_state`` the cloud is told for each state (seed 003: 0 disconnected, 1 connecting, 2 connected).
DRC_STATE = {State.IDLE: 0, State.CONNECTING: 1, State.ACTIVE: 2, State.HOLDING: 2, State.EXITING: 0}
_LIVE = frozenset({State.ACTIVE, State.HOLDING})


class Hold(enum.Enum):
    """Why a HOLDING session holds zero."""

    ESTOP = "emergency_stop"
    HEARTBEAT = "heartbeat"


@dataclass(frozen=True, slots=True)
class SessionConfig:
    stick_timeout: float = 0.5
    heartbeat_timeout: float = 3.0
    idle_timeout: float = 60.0


@dataclass(frozen=True, slots=True)
class LinkSpec:
    """Which DRC broker link a session uses: ``key`` identifies it (two enters with the same key ask
    for the same link), ``dedicated`` is False when the session rides the main connection."""

    key: Hashable
    dedicated: bool


# ----------------------------------------------------------------------------------------- events
@dataclass(frozen=True, slots=True)
class Enter:
    at: float
    request: Hashable
    link: LinkSpec


@dataclass(frozen=True, slots=True)
class Exit:
    at: float
    request: Hashable


@dataclass(frozen=True, slots=True)
class LinkUp:
    at: float
    session: int


@dataclass(frozen=True, slots=True)
class LinkFailed:
    at: float
    session: int
    result: int


@dataclass(frozen=True, slots=True)
class LinkClosed:
    at: float
    session: int


@dataclass(frozen=True, slots=True)
class Stick:
    """One ``drone_control`` or ``stick_control``: ``setpoint`` already in the body frame;
    ``authorized`` as the caller found the control authority when it arrived; ``session`` the link it
    came in on."""

    at: float
    session: int | None
    request: Hashable
    seq: int
    setpoint: SetPoint
    authorized: bool = True
    denied_result: int = NO_FLIGHT_AUTHORITY
    denied_reason: str = ""  # why it is not authorized (no authority, an automatic task flies the device)


@dataclass(frozen=True, slots=True)
class Heartbeat:
    at: float
    session: int | None
    request: Hashable


@dataclass(frozen=True, slots=True)
class EStop:
    at: float
    session: int | None
    request: Hashable


@dataclass(frozen=True, slots=True)
class PayloadCommand:
    """A drc/down command that moves a payload once (``drc_gimbal_reset``): carried out only while the
    session drives freely; the caller checks authority and routes it (:class:`Forward`)."""

    at: float
    session: int | None
    request: Hashable


@dataclass(frozen=True, slots=True)
class Tick:
    at: float


@dataclass(frozen=True, slots=True)
class BrokerLost:
    at: float
    session: int


@dataclass(frozen=True, slots=True)
class AuthorityLost:
    at: float


@dataclass(frozen=True, slots=True)
class Shutdown:
    at: float


Event = (
    Enter | Exit | LinkUp | LinkFailed | LinkClosed | Stick | Heartbeat | EStop | PayloadCommand | Tick
    | BrokerLost | AuthorityLost | Shutdown
)  # fmt: skip


# ---------------------------------------------------------------------------------------- actions
@dataclass(frozen=True, slots=True)
class Motion:
    """Every driven device holds ``setpoint`` from now; ``stream``: keep sending it each period (False:
    send it once, then nothing: the session is over). ``since``: when the set-point was asked for."""

    setpoint: SetPoint
    stream: bool
    since: float


@dataclass(frozen=True, slots=True)
class EmergencyStop:
    """Every device brakes now (not only the driven ones)."""


@dataclass(frozen=True, slots=True)
class OpenLink:
    session: int
    link: LinkSpec


@dataclass(frozen=True, slots=True)
class CloseLink:
    """Close the session's link (or stop opening it); answer with :class:`LinkClosed`."""

    session: int
    link: LinkSpec


@dataclass(frozen=True, slots=True)
class Report:
    """The drc_state changed: publish it (``drc_status_notify`` with ``result``, and the osd)."""

    drc_state: int
    result: int


@dataclass(frozen=True, slots=True)
class Notify:
    """A ``drc_status_notify`` without a state change (heartbeats lost: 514301; resumed: 0)."""

    drc_state: int
    result: int


@dataclass(frozen=True, slots=True)
class Reply:
    """Answer a session request (``drc_mode_enter`` / ``drc_mode_exit``)."""

    request: Hashable
    result: int
    reason: str | None = None


@dataclass(frozen=True, slots=True)
class StickReply:
    """Answer on ``drc/up``: a ``drone_control`` (with its seq), an echo of a ``heart_beat`` or an
    ``drone_emergency_stop`` reply, by the kind of the request."""

    request: Hashable
    result: int
    seq: int | None = None
    reason: str | None = None


@dataclass(frozen=True, slots=True)
class Forward:
    """Carry out a :class:`PayloadCommand` (and answer it with the device's result)."""

    request: Hashable


@dataclass(frozen=True, slots=True)
class Failsafe:
    """A failsafe fired (count it, log it, tell the monitor); ``None``: the last one cleared."""

    reason: str | None
    at: float
    fired: bool = True  # False: an older failsafe that still holds is the one to show again


@dataclass(frozen=True, slots=True)
class Count:
    """A message was dropped or refused, by reason (``not_entered``, ``seq``, ``authority``, ``held``)."""

    reason: str


Action = (
    Motion | EmergencyStop | OpenLink | CloseLink | Report | Notify | Reply | StickReply | Forward | Failsafe
    | Count
)  # fmt: skip


@dataclass(slots=True)
class _Session:
    id: int
    link: LinkSpec
    enter: Hashable | None  # the request that opened it, until answered
    last_seq: int | None = None
    last_stick: float = float("-inf")
    sticks_fresh: bool = False  # the set-point comes from a stick younger than stick_timeout
    last_heartbeat: float = 0.0
    holds: set[Hold] = field(default_factory=set)  # why a HOLDING session holds zero (both may)
    exit_requests: list[Hashable] = field(default_factory=list)  # answered once the link is closed
    exit_result: int = SUCCESS


class DrcSession:
    """One gateway's DRC session state machine. Not thread-safe: the caller serialises :meth:`handle`."""

    def __init__(self, config: SessionConfig | None = None) -> None:
        self.config = config or SessionConfig()
        self.state = State.IDLE
        self.setpoint: SetPoint = ZERO
        self.failsafe: str | None = None  # the failsafe holding or last fired, None when driving freely
        #: when the failsafe's incident began (the ``at`` of the event that fired it first); one value per
        #: incident: a failsafe firing again while it holds keeps it, a new incident starts a new one
        self.failsafe_since: float | None = None
        self.closed = False  # after Shutdown: every Enter is refused
        self._session: _Session | None = None
        self._next_id = 1
        self._queue: deque[Enter | Exit] = deque()
        self._handlers: dict[type, Callable[[_Out, object], None]] = {
            Enter: self._on_enter_or_exit,
            Exit: self._on_enter_or_exit,
            LinkUp: self._on_link_up,
            LinkFailed: self._on_link_failed,
            LinkClosed: self._on_link_closed,
            Stick: self._on_stick,
            Heartbeat: self._on_heartbeat,
            EStop: self._on_estop,
            PayloadCommand: self._on_payload_command,
            Tick: self._on_tick,
            BrokerLost: self._on_broker_lost,
            AuthorityLost: self._on_authority_lost,
            Shutdown: self._on_shutdown,
        }

    # --------------------------------------------------------------------------------- observers
    @property
    def drc_state(self) -> int:
        return DRC_STATE[self.state]

    @property
    def session_id(self) -> int | None:
        """The current session (the one a link's messages must name), None when there is none."""
        return self._session.id if self._session is not None else None

    @property
    def link(self) -> LinkSpec | None:
        return self._session.link if self._session is not None else None

    @property
    def queued(self) -> int:
        return len(self._queue)

    def snapshot(self, now: float) -> dict[str, object]:
        """What a status page shows: state, hold, last seq, heartbeat and stick ages (s)."""
        s = self._session if self.state in _LIVE else None

        def age(t: float) -> float | None:
            return round(now - t, 3) if s is not None and t != float("-inf") else None

        return {
            "session_state": self.state.value,
            "hold": ",".join(sorted(h.value for h in s.holds)) or None if s is not None else None,
            "last_seq": s.last_seq if s is not None else None,
            "heartbeat_age_s": age(s.last_heartbeat) if s is not None else None,
            "stick_age_s": age(s.last_stick) if s is not None else None,
            "failsafe": self.failsafe,
            "failsafe_age_s": round(now - self.failsafe_since, 3)
            if self.failsafe_since is not None
            else None,
        }

    # ----------------------------------------------------------------------------------- driver
    def handle(self, event: Event) -> list[Action]:
        out = _Out()
        self._handlers[type(event)](out, event)
        return out.actions

    # ------------------------------------------------------------------------- session changes
    def _on_enter_or_exit(self, out: _Out, event: object) -> None:
        assert isinstance(event, Enter | Exit)
        self._queue.append(event)
        self._drain(out)

    def _drain(self, out: _Out) -> None:
        """Handle queued enters and exits while no link is being opened or closed."""
        while self._queue and self.state in (State.IDLE, State.ACTIVE, State.HOLDING):
            event = self._queue.popleft()
            if isinstance(event, Enter):
                self._enter(out, event)
            else:
                self._exit(out, event.at, event.request, SUCCESS)

    def _enter(self, out: _Out, event: Enter) -> None:
        if self.closed:
            out.add(Reply(event.request, BUSY, "the gateway is stopping"))
            return
        s = self._session
        if s is not None and self.state in _LIVE:
            if s.link == event.link:  # the same session asked for again (clouds repeat): no churn
                if Hold.ESTOP in s.holds:
                    # a fresh drc_mode_enter is the operator taking live control again: it ends the
                    # emergency stop's hold (the set-point stays zero until the next stick), so a client
                    # whose seq only increases is not locked out (DJI documents no release; issue #33)
                    self._release(out, s, Hold.ESTOP, event.at)
                out.add(Reply(event.request, SUCCESS))
                return
            # another broker: end this session first; the enter is handled once its link is closed
            self._queue.appendleft(event)
            self._end(out, event.at, SUCCESS)
            return
        session = _Session(id=self._next_id, link=event.link, enter=event.request)
        self._next_id += 1
        self._session = session
        self._set_state(out, State.CONNECTING, SUCCESS)
        out.add(OpenLink(session.id, session.link))

    def _exit(self, out: _Out, at: float, request: Hashable | None, result: int) -> None:
        s = self._session
        if s is None or self.state not in _LIVE:
            if request is not None:
                out.add(Reply(request, SUCCESS))
            return
        if request is not None:
            s.exit_requests.append(request)
        self._end(out, at, result)

    def _end(self, out: _Out, at: float, result: int) -> None:
        """Stop motion, report 0 and close the link (the session is over from here)."""
        s = self._session
        assert s is not None
        s.exit_result = result
        self._zero(out, at, stream=False)
        self._set_state(out, State.EXITING, result)
        out.add(CloseLink(s.id, s.link))

    def _on_link_up(self, out: _Out, event: object) -> None:
        assert isinstance(event, LinkUp)
        s = self._session
        if s is None or s.id != event.session or self.state is not State.CONNECTING:
            return  # a link the machine no longer waits for (its CloseLink is already out)
        s.last_heartbeat = event.at  # the session starts alive: the heartbeat limits count from here
        s.last_seq, s.sticks_fresh = None, False
        s.holds.clear()
        self.setpoint = ZERO
        if self.failsafe is not None:  # left from a session before: nothing of it holds in this one
            self._clear_failsafe(out, event.at)
        out.add(Motion(ZERO, True, event.at))
        self._set_state(out, State.ACTIVE, SUCCESS)
        if s.enter is not None:
            out.add(Reply(s.enter, SUCCESS))
            s.enter = None
        self._drain(out)

    def _on_link_failed(self, out: _Out, event: object) -> None:
        assert isinstance(event, LinkFailed)
        s = self._session
        if s is None or s.id != event.session or self.state is not State.CONNECTING:
            return
        self._session = None
        self._set_state(out, State.IDLE, event.result)
        if s.enter is not None:
            out.add(Reply(s.enter, event.result, "could not connect to the DRC broker"))
        self._drain(out)

    def _on_link_closed(self, out: _Out, event: object) -> None:
        assert isinstance(event, LinkClosed)
        s = self._session
        if s is None or s.id != event.session or self.state is not State.EXITING:
            return
        self._session = None
        self.state = State.IDLE  # drc_state was already reported 0 on entering EXITING
        if self.failsafe is not None:  # the session is over: so is its failsafe
            self._clear_failsafe(out, event.at)
        if s.enter is not None:  # shut down while connecting
            out.add(Reply(s.enter, BUSY, "the gateway is stopping"))
        for request in s.exit_requests:
            out.add(Reply(request, SUCCESS))
        self._drain(out)
        if self.closed:
            self._refuse_queue(out)

    def _on_shutdown(self, out: _Out, event: object) -> None:
        assert isinstance(event, Shutdown)
        self.closed = True
        s = self._session
        if s is not None and self.state in _LIVE:
            self._end(out, event.at, SUCCESS)
        elif s is not None and self.state is State.CONNECTING:
            self._zero(out, event.at, stream=False)
            self._set_state(out, State.EXITING, SUCCESS)
            out.add(CloseLink(s.id, s.link))
        elif self.state is State.IDLE:
            self._zero(out, event.at, stream=False)
        if self.state is State.IDLE:
            self._refuse_queue(out)

    def _refuse_queue(self, out: _Out) -> None:
        while self._queue:
            event = self._queue.popleft()
            if isinstance(event, Enter):
                out.add(Reply(event.request, BUSY, "the gateway is stopping"))
            else:
                out.add(Reply(event.request, SUCCESS))

    # ----------------------------------------------------------------------------- drc/down
    def _current(self, session: int | None) -> _Session | None:
        s = self._session
        if s is None or self.state not in _LIVE or session != s.id:
            return None
        return s

    def _on_stick(self, out: _Out, event: object) -> None:
        assert isinstance(event, Stick)
        s = self._current(event.session)
        if s is None:
            out.add(Count("not_entered"))
            return
        if self._expire(out, event.at):
            s = self._current(event.session)
            if s is None:
                out.add(Count("not_entered"))
                return
        seq = event.seq
        if seq != 0 and s.last_seq is not None:
            if seq < s.last_seq:
                out.add(Count("seq"))
                out.add(StickReply(event.request, DRC_SEQ_TOO_OLD, seq))
                return
            if seq == s.last_seq:
                out.add(Count("repeat"))
                return  # clouds publish each DRC message several times: one effect, one answer
        if not event.authorized:
            out.add(Count("authority"))
            reason = event.denied_reason or "no control authority"
            out.add(StickReply(event.request, event.denied_result, seq, reason))
            return
        if Hold.HEARTBEAT in s.holds:
            out.add(Count("held"))
            reason = "no heartbeat: held until heartbeats resume"
            out.add(StickReply(event.request, DRC_HEARTBEAT_TIMEOUT, seq, reason))
            return
        if Hold.ESTOP in s.holds:
            if seq != 0:
                out.add(Count("held"))
                out.add(StickReply(event.request, BUSY, seq, _ESTOP_HOLDS))
                return
            self._release(out, s, Hold.ESTOP, event.at)  # seq 0 after an emergency stop: drive again
        s.last_seq = seq
        s.last_stick = event.at
        s.sticks_fresh = True
        if self.failsafe is not None:  # a stick or authority failsafe: the operator drives again
            self._clear_failsafe(out, event.at)
        self.setpoint = event.setpoint
        out.add(Motion(event.setpoint, True, event.at))
        out.add(StickReply(event.request, SUCCESS, seq))

    def _on_heartbeat(self, out: _Out, event: object) -> None:
        assert isinstance(event, Heartbeat)
        s = self._current(event.session)
        if s is None:
            out.add(Count("not_entered"))
            return
        out.add(StickReply(event.request, SUCCESS))
        s.last_heartbeat = event.at
        if Hold.HEARTBEAT in s.holds:
            self._release(out, s, Hold.HEARTBEAT, event.at)
            out.add(Notify(2, SUCCESS))

    def _on_estop(self, out: _Out, event: object) -> None:
        assert isinstance(event, EStop)
        s = self._current(event.session)
        if s is not None and Hold.ESTOP in s.holds:
            out.add(StickReply(event.request, SUCCESS))  # a repeat: stopped once, answered each time
            return
        self._zero(out, event.at, stream=s is not None)
        out.add(EmergencyStop())
        self._fire(out, "emergency_stop", event.at)
        if s is not None:
            s.holds.add(Hold.ESTOP)
            s.sticks_fresh = False
            self.state = State.HOLDING
        out.add(StickReply(event.request, SUCCESS))

    def _on_payload_command(self, out: _Out, event: object) -> None:
        assert isinstance(event, PayloadCommand)
        s = self._current(event.session)
        if s is not None and self._expire(out, event.at):
            s = self._current(event.session)
        if s is None:
            out.add(Count("not_entered"))
            return
        if Hold.HEARTBEAT in s.holds:
            out.add(Count("held"))
            reason = "no heartbeat: held until heartbeats resume"
            out.add(StickReply(event.request, DRC_HEARTBEAT_TIMEOUT, None, reason))
        elif Hold.ESTOP in s.holds:
            out.add(Count("held"))
            out.add(StickReply(event.request, BUSY, None, _ESTOP_HOLDS))
        else:
            out.add(Forward(event.request))

    # ------------------------------------------------------------------------------- losses
    def _on_tick(self, out: _Out, event: object) -> None:
        assert isinstance(event, Tick)
        self._expire(out, event.at)

    def _expire(self, out: _Out, at: float) -> bool:
        """Apply the timeouts as of ``at``; True when one fired. Run on every tick and before every
        stick, so a stick can never drive past a deadline that no tick has noticed yet."""
        s = self._session
        if s is None or self.state not in _LIVE:
            return False
        silent = at - s.last_heartbeat
        if silent > self.config.idle_timeout:
            self._exit(out, at, None, DRC_HEARTBEAT_TIMEOUT)
            return True
        if silent > self.config.heartbeat_timeout and Hold.HEARTBEAT not in s.holds:
            s.holds.add(Hold.HEARTBEAT)
            s.sticks_fresh = False
            self.state = State.HOLDING
            self._zero(out, at, stream=True)
            self._fire(out, "heartbeat", at)
            out.add(Notify(2, DRC_HEARTBEAT_TIMEOUT))
            return True
        if s.sticks_fresh and at - s.last_stick > self.config.stick_timeout:
            s.sticks_fresh = False
            if self.setpoint != ZERO:
                self._zero(out, at, stream=True)
                self._fire(out, "sticks", at)
            return True
        return False

    def _on_broker_lost(self, out: _Out, event: object) -> None:
        assert isinstance(event, BrokerLost)
        s = self._session
        if s is None or s.id != event.session or self.state not in _LIVE:
            return
        self._fire(out, "link_lost", event.at)
        self._exit(out, event.at, None, DRC_LINK_LOST)

    def _on_authority_lost(self, out: _Out, event: object) -> None:
        assert isinstance(event, AuthorityLost)
        s = self._session
        if s is None or self.state not in _LIVE:
            return
        s.sticks_fresh = False
        self._zero(out, event.at, stream=True)
        self._fire(out, "authority", event.at)

    # ------------------------------------------------------------------------------ helpers
    def _release(self, out: _Out, s: _Session, hold: Hold, at: float) -> None:
        s.holds.discard(hold)
        if s.holds:  # the other failsafe still holds: it is the one to show
            self.failsafe = next(iter(s.holds)).value
            out.add(Failsafe(self.failsafe, at, fired=False))
            return
        self.state = State.ACTIVE
        self._clear_failsafe(out, at)

    def _zero(self, out: _Out, at: float, *, stream: bool) -> None:
        self.setpoint = ZERO
        out.add(Motion(ZERO, stream, at))

    def _fire(self, out: _Out, reason: str, at: float) -> None:
        if self.failsafe != reason or self.failsafe_since is None:
            self.failsafe_since = at  # a new incident (the same one firing again keeps its start)
        self.failsafe = reason
        out.add(Failsafe(reason, at))

    def _clear_failsafe(self, out: _Out, at: float) -> None:
        self.failsafe = None
        self.failsafe_since = None
        out.add(Failsafe(None, at))

    def _set_state(self, out: _Out, state: State, result: int) -> None:
        before = DRC_STATE[self.state]
        self.state = state
        if DRC_STATE[state] != before or result != SUCCESS:
            out.add(Report(DRC_STATE[state], result))


class _Out:
    __slots__ = ("actions",)

    def __init__(self) -> None:
        self.actions: list[Action] = []

    def add(self, action: Action) -> None:
        self.actions.append(action)
