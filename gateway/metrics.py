"""In-process counters, gauges and latency samples for the gateway.

Owns the numbers only (no HTTP, no Prometheus types) so every layer can count without a
dependency; an exporter (``gateway.observability``) reads :meth:`Metrics.snapshot`. ``observe`` keeps
a window of recent samples (for percentiles in benchmarks) and a cumulative histogram per label set
(for Prometheus: buckets never forget, a window would). Updated from the event loop and from other
threads (paho's network threads, the motion writer, the link threads' callers), read from the web
thread: one lock guards every update and every read (``d[k] += 1`` is a read and a write, and a dict
that gains a key while another thread iterates it raises), held for a few dict operations only.
"""

from __future__ import annotations

import threading
from collections import defaultdict, deque
from dataclasses import dataclass, field

Labels = tuple[tuple[str, str], ...]

#: Upper bounds (seconds) of the latency histograms: a reply is due within 3 s, devices answer in ms.
LATENCY_BUCKETS: tuple[float, ...] = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0)


def _labels(kw: dict[str, object]) -> Labels:
    return tuple(sorted((k, str(v)) for k, v in kw.items()))


@dataclass
class Histogram:
    """Cumulative bucket counts (``counts[i]``: observations <= ``bounds[i]``; the last slot is +Inf)."""

    bounds: tuple[float, ...] = LATENCY_BUCKETS
    counts: list[int] = field(default_factory=list)
    total: float = 0.0
    count: int = 0

    def add(self, value: float) -> None:
        if not self.counts:
            self.counts = [0] * (len(self.bounds) + 1)
        for i, bound in enumerate(self.bounds):
            if value <= bound:
                self.counts[i] += 1
        self.counts[-1] += 1
        self.total += value
        self.count += 1


@dataclass
class Metrics:
    counters: dict[tuple[str, Labels], float] = field(default_factory=lambda: defaultdict(float))
    gauges: dict[tuple[str, Labels], float] = field(default_factory=dict)
    samples: dict[str, deque[float]] = field(default_factory=dict)
    histograms: dict[tuple[str, Labels], Histogram] = field(default_factory=dict)
    sample_window: int = 4096
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def inc(self, name: str, amount: float = 1.0, **labels: object) -> None:
        key = (name, _labels(labels))
        with self.lock:
            self.counters[key] += amount

    def set(self, name: str, value: float, **labels: object) -> None:
        key = (name, _labels(labels))
        with self.lock:
            self.gauges[key] = value

    def observe(self, name: str, value: float, **labels: object) -> None:
        key = (name, _labels(labels))
        with self.lock:
            window = self.samples.get(name)
            if window is None:
                window = self.samples[name] = deque(maxlen=self.sample_window)
            window.append(value)
            hist = self.histograms.get(key)
            if hist is None:
                hist = self.histograms[key] = Histogram()
            hist.add(value)

    def count(self, name: str, **labels: object) -> float:
        """Sum of a counter over every label set that includes ``labels``."""
        want = set(_labels(labels))
        with self.lock:
            items = list(self.counters.items())
        return sum(v for (n, lab), v in items if n == name and want <= set(lab))

    def gauge(self, name: str, **labels: object) -> float | None:
        with self.lock:
            return self.gauges.get((name, _labels(labels)))

    def snapshot(self) -> dict[str, object]:
        with self.lock:
            counters, gauges = list(self.counters.items()), list(self.gauges.items())
        return {
            "counters": [{"name": n, "labels": dict(lab), "value": v} for (n, lab), v in counters],
            "gauges": [{"name": n, "labels": dict(lab), "value": v} for (n, lab), v in gauges],
        }
