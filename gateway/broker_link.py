"""The broker connection's decisions, without the I/O: which broker node to try, when, and what a
pattern of losses means. Also the bounded buffer that holds telemetry while no broker can take it.

Theory of operation. :class:`gateway.mqtt.MqttBridge` owns the sockets and paho; it asks a
:class:`ReconnectPolicy` what to do and tells it what happened, always passing the clock's value
(``now``), so every rule here is tested without a socket or a sleep (``tests/test_broker_link.py``).

* **Finding a broker.** While no connection is up the bridge *probes*: a non-blocking TCP connect to
  every configured URL at once, a round every ``probe_interval`` (drawn from [½·p, p], so a fleet does
  not synchronise). A probe costs one SYN: as cheap for the broker as a failed MQTT attempt, and it is
  what makes the gateway come back within about ``probe_interval`` of the broker or the network
  returning, whatever the outage lasted (a growing backoff would wait longer the longer the outage).
  The first node that answers gets the MQTT CONNECT; when several answer in one poll, the node after
  the one last used comes first (a node that just died is tried last).
* **First round after a loss**: after a random pause in [0, ``reconnect_min``] (the gateways of a
  dead node do not all land on the next node in the same millisecond).
* **A broker that answers and then fails the attempt** (no CONNACK within the attempt's deadline, closed
  before the CONNACK, a CONNACK refusal, TLS refused): while other nodes are untried in this cycle, the
  next one is tried after a pause up to :data:`NEXT_NODE_JITTER` (no long backoff while another node may
  serve). Once every node failed: a *busy* cluster (no CONNACK, closed before it, "server unavailable" or
  "busy": NATS while JetStream elects its leaders) backs off ``reconnect_min`` doubling up to
  :data:`BUSY_BACKOFF_MAX` (1 s); a *refusal* (credentials, TLS) ``reconnect_min`` doubling up to
  ``reconnect_max``; both jittered (½–1× the ceiling). With several nodes a node that has our CONNECT
  (TCP acknowledged it) and sends no CONNACK within :data:`CONNACK_FIRST` (1 s) is left for the next;
  a CONNECT TCP has not delivered yet (a slow link) gets ``connect_timeout``. A cycle is over the nodes
  that answered the last probe round (a dead node is never tried, so it cannot hold a cycle open).
  Probing does not shorten any of this: hammering a broker that refuses helps no one. Fleet bound: while
  a cluster is not ready, one gateway makes at most one attempt per node per cycle, and waits at least
  ``reconnect_min``/4 (0.125 s by default), then ``reconnect_min``/2 … ½ s, between cycles.
* **Client-id takeover**: an MQTT 5 disconnect with reason 0x8E (session taken over), or
  :data:`TAKEOVER_STREAK` connections in a row closed by the broker within :data:`SHORT_LIVED` seconds
  of their CONNACK (MQTT 3.1.1 has no reason to give; mosquitto 2.0 closes an MQTT 5 connection that is
  taken over without one too): another client uses the same id. Backoff doubles from :data:`TAKEOVER_FIRST` to
  ``takeover_backoff_max`` (≥ 30 s); the suspicion clears once a connection has lasted
  :data:`STABLE_AFTER` seconds. A probe round that no node answered ends a streak: the connections
  before it were closed by an outage (broker or network down), not by a twin, which needs the broker up.
* **Stalled connection**: the bridge reports a connection whose oldest unacknowledged segment has
  been retransmitted repeatedly (TCP's own view, ``TCP_INFO``). It then probes; when a node answers
  while the old connection is still stuck (TCP would wait out its grown retransmission timer, up to
  two minutes), the bridge drops it and connects at once.
* **Deaf connection** (:class:`LivenessProbe`): connected and subscribed is not proof of receiving (a
  NATS cluster electing its JetStream leader acknowledged a subscription and delivered nothing for 30 s).
  After every SUBACK, and then every ``interval`` (jittered to ½–1×) while the link is proven, the bridge
  publishes a probe to a topic the link is subscribed to; it must come back within a deadline: ``timeout``
  on a connection that has proven itself, and on one that has not (just made, or resubscribed before any
  proof) a *quick* deadline, :data:`QUICK_FACTOR` × the link's slowest recent round trip, at least
  :data:`QUICK_MIN` (no round trip known yet: ``timeout``). The first miss marks the link *deaf* and
  resubscribes; a second miss on the same connection drops it (:attr:`Loss.DEAF`) and the policy connects
  again at once (after a jitter up to ``reconnect_min``/2), the next node first. A probe that comes back
  late still proves the link receives (slow, not deaf), and its round trip widens later quick deadlines.
  The link stays deaf, whatever node it is on, until a probe comes back.

Knows nothing of paho, sockets or topics.
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass
from enum import Enum

__all__ = [
    "BUSY_BACKOFF_MAX",
    "CONNACK_FIRST",
    "NEXT_NODE_JITTER",
    "QUICK_FACTOR",
    "QUICK_MIN",
    "SHORT_LIVED",
    "STABLE_AFTER",
    "TAKEOVER_FIRST",
    "TAKEOVER_STREAK",
    "Liveness",
    "LivenessProbe",
    "Loss",
    "OfflineBuffer",
    "ProbeStep",
    "ReconnectPolicy",
]

#: A connection closed by the broker this soon after its CONNACK counts towards a takeover streak (3.1.1).
SHORT_LIVED = 3.0
#: This many short-lived connections in a row mean another client uses our id (when no 0x8E says so).
TAKEOVER_STREAK = 3
#: The first wait after a takeover; it doubles up to ``takeover_backoff_max``.
TAKEOVER_FIRST = 2.0
#: A connection that lasted this long clears a takeover suspicion and the refusal backoff.
STABLE_AFTER = 30.0
#: Attempts that fail the way a broker fails while its cluster is not ready (no CONNACK in time, closed
#: before the CONNACK, CONNACK "server unavailable/busy") back off at most this long (s) once every node
#: has been tried: the cluster serves again within this of its recovery, for the whole fleet.
BUSY_BACKOFF_MAX = 1.0
#: While other nodes are untried after a failed attempt, the next one is tried after a random pause up to
#: this (s): a fleet's gateways do not reach the next node in the same millisecond.
NEXT_NODE_JITTER = 0.1
#: The CONNACK deadline with several nodes once TCP has acknowledged the CONNECT (s): the broker has it
#: and sits on it (see :meth:`ReconnectPolicy.connack_timeout`).
CONNACK_FIRST = 1.0
#: A probe on a connection not proven yet must be back within this many times the link's slowest recent
#: round trip, at least :data:`QUICK_MIN` s (see :meth:`LivenessProbe.quick_deadline`).
QUICK_FACTOR = 4.0
QUICK_MIN = 0.3
#: Round trips (and probes sent) remembered per link.
RTT_KEPT = 8


class Loss(Enum):
    """How a connection ended, as far as the bridge can tell."""

    CLOSED = "closed"  # the broker closed it (or the network reset it)
    TAKEN_OVER = "taken_over"  # MQTT 5 DISCONNECT with reason 0x8E
    STALLED = "stalled"  # we dropped it: the path was stuck while a node answered probes
    DEAF = "deaf"  # we dropped it: subscribed, yet our own probe never came back (twice)


class ReconnectPolicy:
    """When to probe, which node to use, how long to back off; see the module docstring."""

    def __init__(
        self,
        endpoints: int,
        *,
        reconnect_min: float,
        reconnect_max: float,
        probe_interval: float,
        takeover_backoff_max: float,
        rng: random.Random | None = None,
    ) -> None:
        if endpoints < 1:
            raise ValueError("at least one endpoint")
        self.endpoints = endpoints
        self.reconnect_min, self.reconnect_max = reconnect_min, max(reconnect_min, reconnect_max)
        self.probe_interval = probe_interval
        self.takeover_backoff_max = max(TAKEOVER_FIRST, takeover_backoff_max)
        self._rng = rng or random.Random()
        self.last_index = endpoints - 1  # so the first choice is endpoint 0
        self._tried: set[int] = set()  # nodes that failed an attempt since the last CONNACK (this cycle)
        self._busy_cycles = 0  # full cycles of every node failing as a busy cluster does
        self._candidates: set[int] = set(range(endpoints))  # the nodes that answered the last probe
        self._refusals = 0
        self._short_streak = 0
        self._takeovers = 0  # consecutive takeovers (the backoff exponent)
        self.takeover_suspected = False
        self.takeover_count = 0  # every takeover seen (for the metric)

    # -- choosing ---------------------------------------------------------------------------------
    def choose(self, answered: set[int]) -> int:
        """Of the nodes that answered a probe, the first in rotation order after the last one used."""
        self._candidates = set(answered)
        for step in range(1, self.endpoints + 1):
            index = (self.last_index + step) % self.endpoints
            if index in answered:
                return index
        raise ValueError("no endpoint answered")

    def attempt(self, index: int) -> None:
        """A CONNECT goes to ``index`` now: the next choice starts after it (a node that failed the
        attempt is tried again only after the others)."""
        self.last_index = index

    def connack_timeout(self, connect_timeout: float) -> float:
        """How long to wait for this attempt's CONNACK once the broker has our CONNECT (TCP acknowledged
        it): with several nodes :data:`CONNACK_FIRST`, one node ``connect_timeout``. A node that has the
        CONNECT and does not answer (NATS while JetStream has no leader: it answers only when its own
        request to JetStream times out, 4 s later) is left for the next one quickly; while the CONNECT is
        still unacknowledged by TCP (a slow link), the bridge waits up to ``connect_timeout``."""
        return connect_timeout if self.endpoints == 1 else min(connect_timeout, CONNACK_FIRST)

    def next_round(self, now: float) -> float:
        """When the next probe round starts, after one that found nobody."""
        return now + self._rng.uniform(self.probe_interval / 2, self.probe_interval)

    # -- outcomes ---------------------------------------------------------------------------------
    def connected(self, now: float, index: int) -> None:
        """CONNACK accepted on ``index``."""
        self.last_index = index
        self._tried.clear()
        self._busy_cycles = 0

    def unreachable(self, now: float) -> None:
        """A probe round found no node (or the chosen one was gone before the CONNECT): the broker or the
        network is down. The short connections before it were ended by that outage, not by another client
        with our id (a twin can only take our session over while the broker is up): the streak ends."""
        self._short_streak = 0

    def refused(self, now: float, *, busy: bool = False) -> float:
        """The attempt on the last node chosen failed after the broker answered: when to probe again.

        While other nodes that answered the last probe round are untried in this cycle: after a pause
        up to :data:`NEXT_NODE_JITTER` (the next node comes first). Once every node failed: ``busy`` (no
        CONNACK in time, closed before it, "server unavailable"/"busy": a cluster that is not ready)
        backs off ``reconnect_min`` doubling up to :data:`BUSY_BACKOFF_MAX`; a refusal (credentials, TLS)
        ``reconnect_min`` doubling up to ``reconnect_max``; both drawn from ½–1× the ceiling."""
        self._tried.add(self.last_index)
        if self._candidates - self._tried:  # a node that answers the probes has not been tried yet
            return now + self._rng.uniform(0.0, min(NEXT_NODE_JITTER, self.reconnect_min))
        self._tried.clear()
        if busy:
            self._busy_cycles += 1
            cap = max(self.reconnect_min, min(BUSY_BACKOFF_MAX, self.reconnect_max))
            ceiling = min(cap, self.reconnect_min * 2 ** min(self._busy_cycles - 1, 32))
            return now + self._rng.uniform(ceiling / 2, ceiling)
        self._refusals += 1
        ceiling = min(self.reconnect_max, self.reconnect_min * 2 ** min(self._refusals - 1, 32))
        return now + self._rng.uniform(ceiling / 2, ceiling)

    def lost(self, now: float, *, lasted: float, how: Loss) -> float:
        """A connection that had its CONNACK ended after ``lasted`` seconds: when to probe again."""
        if lasted >= STABLE_AFTER:
            self._refusals = self._short_streak = self._takeovers = 0
            self.takeover_suspected = False
        if how is Loss.TAKEN_OVER:
            return self._taken_over(now)
        if how is Loss.STALLED:
            self._short_streak = 0
            return now  # a node answered a probe a moment ago: connect at once
        if how is Loss.DEAF:  # the broker is up but does not deliver: the next node, soon (a fleet spread)
            self._short_streak = 0
            return now + self._rng.uniform(0.0, self.reconnect_min / 2)
        if lasted < SHORT_LIVED:
            self._short_streak += 1
            if self.takeover_suspected or self._short_streak >= TAKEOVER_STREAK:
                return self._taken_over(now)
            if self._short_streak > 1:  # a broker that keeps closing us at once: back off as for a refusal
                return self.refused(now, busy=True)
        else:
            self._short_streak = 0
        return now + self._rng.uniform(0.0, self.reconnect_min)

    def _taken_over(self, now: float) -> float:
        self.takeover_suspected = True
        self.takeover_count += 1
        self._takeovers += 1
        ceiling = min(self.takeover_backoff_max, TAKEOVER_FIRST * 2.0 ** min(self._takeovers - 1, 32))
        return now + self._rng.uniform(ceiling / 2, ceiling)


class Liveness(Enum):
    """Whether the link has been seen to receive."""

    UNPROVEN = "unproven"  # connected, no probe back yet (and never deaf since the last proof)
    LIVE = "live"  # the last probe came back in time
    DEAF = "deaf"  # a probe missed its deadline; no probe has come back since


class ProbeStep(Enum):
    """What the bridge must do now for the liveness probe."""

    NONE = "none"
    SEND = "send"  # publish the probe :attr:`LivenessProbe.nonce` to the probe topic
    RESUBSCRIBE = "resubscribe"  # first miss on this connection: subscribe again
    RECONNECT = "reconnect"  # missed again after resubscribing: drop the connection (Loss.DEAF)


class LivenessProbe:
    """The end-to-end receive check of one broker link (see the module docstring, "Deaf connection").

    The bridge calls :meth:`subscribed` on every SUBACK, :meth:`received` with every probe payload that
    comes back, :meth:`lost` when the connection ends and :meth:`step` periodically (every 50 ms); ``now``
    is always the injected clock's value. ``interval`` 0 turns it off (:meth:`step` never asks anything).
    """

    def __init__(self, *, interval: float, timeout: float, rng: random.Random | None = None) -> None:
        self.interval, self.timeout = interval, timeout
        self.enabled = interval > 0
        self._rng = rng or random.Random()
        self.state = Liveness.UNPROVEN
        self.nonce = ""
        self._seq = 0
        self._token = f"{self._rng.getrandbits(48):012x}"  # tells our probes from another process's
        self._due: float | None = None  # when the next probe goes out (None: not subscribed)
        self._deadline: float | None = None  # when the outstanding probe must be back
        self._probe_at = 0.0  # when the outstanding probe went out
        self._sent: dict[bytes, float] = {}  # the last few probes sent (nonce → when): a late one proves too
        self._missed = False  # a probe already missed on this connection (we resubscribed)
        self._proven = False  # a probe came back on this connection
        self._rtts: deque[float] = deque(maxlen=RTT_KEPT)
        self.deaf_count = 0  # transitions into DEAF (for the metric)
        self.last_rtt: float | None = None
        self.last_proof: float | None = None  # when a probe last came back (the clock's value)
        self.last_deadline = timeout  # the deadline the last probe had (for the log line)

    @property
    def deaf(self) -> bool:
        return self.state is Liveness.DEAF

    def quick_deadline(self) -> float:
        """The deadline of a probe on a connection not proven yet: :data:`QUICK_FACTOR` × the slowest of
        the last round trips this link made, at least :data:`QUICK_MIN`, at most ``timeout`` (no round trip
        known yet: ``timeout``). A connection made while a cluster elects its leaders is typically deaf
        for good; finding that out in a fraction of a second is most of the gateway's share of a
        failover."""
        if not self._rtts:
            return self.timeout
        return min(self.timeout, max(QUICK_MIN, QUICK_FACTOR * max(self._rtts)))

    def subscribed(self, now: float) -> None:
        """The broker acknowledged the subscriptions (after a connect or a resubscribe): probe now."""
        self._due, self._deadline = now, None

    def lost(self) -> None:
        """The connection ended: nothing outstanding; a deaf link stays deaf until a probe comes back."""
        self._due = self._deadline = None
        self._missed = self._proven = False

    def step(self, now: float, traffic_at: float | None = None) -> ProbeStep:
        """What to do now. ``traffic_at``: when the broker last delivered another message on this link
        (not a probe). A probe missed while other messages kept arriving after it went out proves the link
        receives all the same: on a NATS cluster each topic's subscription is a JetStream consumer with
        a leader of its own, and for seconds after a node dies the probe topic's may have none while the
        cloud's requests flow; treating that as deaf reconnected every 0.7 s for up to 6 s, dropping a
        live-control session on the same broker each time. (A link that delivers some topics and never
        the requests, while the others keep coming, is not told apart by this: docs/brokers.md.)"""
        if not self.enabled:
            return ProbeStep.NONE
        if self._deadline is not None:
            if now < self._deadline:
                return ProbeStep.NONE
            self._deadline = None
            if traffic_at is not None and traffic_at >= self._probe_at:
                self.state = Liveness.LIVE
                self._missed = False
                self._proven = True
                self.last_proof = traffic_at
                self._due = now + self._rng.uniform(self.interval / 2, self.interval)
                return ProbeStep.NONE
            if not self.deaf:
                self.state = Liveness.DEAF
                self.deaf_count += 1
            if not self._missed:
                self._missed = True
                # the next probe goes out on its SUBACK, or after a deadline if that SUBACK is missed
                self._due = now + self._deadline_now()
                return ProbeStep.RESUBSCRIBE
            return ProbeStep.RECONNECT
        if self._due is not None and now >= self._due:
            self._seq += 1
            self.nonce = f"djigw-probe {self._token} {self._seq}"
            self.last_deadline = self._deadline_now()
            self._due, self._deadline = None, now + self.last_deadline
            self._probe_at = now
            self._sent[self.nonce.encode()] = now
            while len(self._sent) > RTT_KEPT:
                del self._sent[next(iter(self._sent))]
            return ProbeStep.SEND
        return ProbeStep.NONE

    def _deadline_now(self) -> float:
        return self.timeout if self._proven else self.quick_deadline()

    def received(self, now: float, payload: bytes) -> bool:
        """A message on the probe topic: True when it is one of our last probes (the link receives, even
        if the probe is late: then it was slow, not deaf, and later deadlines allow for it). Another
        process's probe, or one of ours from long ago, is ignored."""
        sent = self._sent.pop(payload, None)
        if sent is None:
            return False
        self.last_rtt = now - sent
        self.last_proof = now
        self._rtts.append(self.last_rtt)
        self.state = Liveness.LIVE
        self._missed = False
        self._proven = True
        if self._deadline is not None or payload == self.nonce.encode():
            self._deadline = None
            self._due = now + self._rng.uniform(self.interval / 2, self.interval)
        elif self._due is None:  # a late proof while the link waits for nothing: probe again in time
            self._due = now + self._rng.uniform(self.interval / 2, self.interval)
        return True

    def next_at(self) -> float | None:
        """When :meth:`step` next has something to do (a probe due or a deadline), if anything."""
        return self._deadline if self._deadline is not None else self._due


@dataclass(slots=True)
class _Held:
    at: float
    topic: str
    payload: bytes


class OfflineBuffer:
    """Telemetry kept while no broker can take it: at most ``limit`` messages, none older than
    ``max_age`` seconds; the oldest go first, and every drop is counted by reason."""

    def __init__(self, limit: int, max_age: float) -> None:
        self.limit, self.max_age = limit, max_age
        self._items: deque[_Held] = deque()
        self.dropped_overflow = 0
        self.dropped_age = 0

    def __len__(self) -> int:
        return len(self._items)

    def add(self, now: float, topic: str, payload: bytes) -> None:
        if self.limit <= 0:
            self.dropped_overflow += 1
            return
        self._expire(now)
        while len(self._items) >= self.limit:
            self._items.popleft()
            self.dropped_overflow += 1
        self._items.append(_Held(now, topic, payload))

    def _expire(self, now: float) -> None:
        while self._items and now - self._items[0].at > self.max_age:
            self._items.popleft()
            self.dropped_age += 1

    def take(self, now: float) -> list[tuple[float, str, bytes]]:
        """Everything still young enough, oldest first, as ``(at, topic, payload)``; the buffer is
        empty afterwards."""
        self._expire(now)
        out = [(h.at, h.topic, h.payload) for h in self._items]
        self._items.clear()
        return out

    def put_back(self, items: list[tuple[float, str, bytes]]) -> None:
        """Return what could not be sent (the link dropped again mid-flush), ahead of newer items."""
        for at, topic, payload in reversed(items):
            self._items.appendleft(_Held(at, topic, payload))
        while len(self._items) > self.limit:
            self._items.popleft()
            self.dropped_overflow += 1
