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
* **Backoff for a broker that answers and refuses** (CONNACK refused, TLS refused, no CONNACK, closed
  at once): capped exponential with jitter, ``reconnect_min`` doubling up to ``reconnect_max``. Probing
  does not shorten it: hammering a broker that refuses helps no one.
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
  publishes a probe to a topic the link is subscribed to; it must come back within ``timeout``. The first
  miss marks the link *deaf* and resubscribes; a second miss on the same connection drops it
  (:attr:`Loss.DEAF`) and the policy connects again at once (after a jitter up to ``reconnect_min``), the
  next node first. The link stays deaf, whatever node it is on, until a probe comes back.

Knows nothing of paho, sockets or topics.
"""

from __future__ import annotations

import random
from collections import deque
from dataclasses import dataclass
from enum import Enum

__all__ = [
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
        self._refusals = 0
        self._short_streak = 0
        self._takeovers = 0  # consecutive takeovers (the backoff exponent)
        self.takeover_suspected = False
        self.takeover_count = 0  # every takeover seen (for the metric)

    # -- choosing ---------------------------------------------------------------------------------
    def choose(self, answered: set[int]) -> int:
        """Of the nodes that answered a probe, the first in rotation order after the last one used."""
        for step in range(1, self.endpoints + 1):
            index = (self.last_index + step) % self.endpoints
            if index in answered:
                return index
        raise ValueError("no endpoint answered")

    def next_round(self, now: float) -> float:
        """When the next probe round starts, after one that found nobody."""
        return now + self._rng.uniform(self.probe_interval / 2, self.probe_interval)

    # -- outcomes ---------------------------------------------------------------------------------
    def connected(self, now: float, index: int) -> None:
        """CONNACK accepted on ``index``."""
        self.last_index = index

    def unreachable(self, now: float) -> None:
        """A probe round found no node (or the chosen one was gone before the CONNECT): the broker or the
        network is down. The short connections before it were ended by that outage, not by another client
        with our id (a twin can only take our session over while the broker is up): the streak ends."""
        self._short_streak = 0

    def refused(self, now: float) -> float:
        """The broker answered and refused (CONNACK, TLS, no CONNACK): when to probe again."""
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
            return now + self._rng.uniform(0.0, self.reconnect_min)
        if lasted < SHORT_LIVED:
            self._short_streak += 1
            if self.takeover_suspected or self._short_streak >= TAKEOVER_STREAK:
                return self._taken_over(now)
            if self._short_streak > 1:  # a broker that keeps closing us at once: back off as for a refusal
                return self.refused(now)
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
        self._sent_at = 0.0
        self._missed = False  # a probe already missed on this connection (we resubscribed)
        self.deaf_count = 0  # transitions into DEAF (for the metric)
        self.last_rtt: float | None = None

    @property
    def deaf(self) -> bool:
        return self.state is Liveness.DEAF

    def subscribed(self, now: float) -> None:
        """The broker acknowledged the subscriptions (after a connect or a resubscribe): probe now."""
        self._due, self._deadline = now, None

    def lost(self) -> None:
        """The connection ended: nothing outstanding; a deaf link stays deaf until a probe comes back."""
        self._due = self._deadline = None
        self._missed = False

    def step(self, now: float) -> ProbeStep:
        if not self.enabled:
            return ProbeStep.NONE
        if self._deadline is not None:
            if now < self._deadline:
                return ProbeStep.NONE
            self._deadline = None
            if not self.deaf:
                self.state = Liveness.DEAF
                self.deaf_count += 1
            if not self._missed:
                self._missed = True
                # the next probe goes out on its SUBACK, or after ``timeout`` if that SUBACK is missed
                self._due = now + self.timeout
                return ProbeStep.RESUBSCRIBE
            return ProbeStep.RECONNECT
        if self._due is not None and now >= self._due:
            self._seq += 1
            self.nonce = f"djigw-probe {self._token} {self._seq}"
            self._due, self._deadline, self._sent_at = None, now + self.timeout, now
            return ProbeStep.SEND
        return ProbeStep.NONE

    def received(self, now: float, payload: bytes) -> bool:
        """A message on the probe topic: True when it is the outstanding probe (the link receives).
        A late probe from before, or another process's, is ignored."""
        if self._deadline is None or payload != self.nonce.encode():
            return False
        self.last_rtt = now - self._sent_at
        self.state = Liveness.LIVE
        self._missed = False
        self._deadline = None
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
