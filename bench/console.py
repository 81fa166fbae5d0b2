"""The web console's cost to the gateway: CPU with pages open, and service round trips meanwhile.

The gateway is ``dji-gateway run --simulate`` as its own process (three simulated devices: the R SDK
gimbal on a virtual CAN bus, the Onboard SDK aircraft and the RoboMaster robot on loopback serial
ports, all inside that process) against a private mosquitto. Its CPU time is read from
``/proc/<pid>/stat`` (user + system) over a window:

* **no page** (the baseline, measured before and after the pages, averaged);
* **1 page** and **20 pages**: WebSocket clients in a process of their own (as a browser is) that do
  what an open console page does to the gateway: fetch ``/api/catalog`` and ``/api/tracks`` once, then
  read the 10 Hz state push and the frame inspector of the gimbal's CAN link (the busiest link).

Targets (issue #21): one page at 10 Hz with three devices raises the gateway's CPU by at most 5 % of one
core; 20 pages by at most 15 %. Round trips: ``x_rsdk_version_get`` (cloud → mosquitto → gateway → CAN
→ simulated gimbal → back) in the e2e suite's own set-up (gateway and gimbal simulator in this process),
interleaved: with no HTTP endpoint at all (reported against the bare broker echo, as the e2e suite does),
with the console on and no page, with one page (another process) reading it, and with that page watching
the gimbal's frames — each held to the e2e margins (p50 ≤ +1 ms, p99 ≤ +3 ms) over the gateway without
its HTTP endpoint measured in the same rounds, so the rows say what the console costs, not how loaded
the machine is.
"""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import aiohttp

from adapters.rsdk.sim import GimbalCanSim
from bench.e2e import _pct, _Timer, bare_echo
from bench.run import ROOT, Config, Row
from gateway.local_broker import LocalBroker
from gateway.settings import load_settings
from tests.support import GatewayThread, simulated_gateway

GW = "DJIGW-SIM-0001"
GIMBAL = "RSDK-SIM-0001"
TICK = os.sysconf("SC_CLK_TCK")


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK  # utime + stime


def _cpu_percent(pid: int, seconds: float) -> float:
    c0, t0 = _cpu_seconds(pid), time.monotonic()
    time.sleep(seconds)
    return 100.0 * (_cpu_seconds(pid) - c0) / (time.monotonic() - t0)


class Pages:
    """``n`` console pages (WebSocket clients) on their own loop in a thread, until :meth:`close`."""

    def __init__(self, url: str, n: int, frames: bool = True) -> None:
        self.url, self.n, self.watch_frames = url, n, frames
        self.states = 0
        self.frames = 0
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), daemon=True)
        self._thread.start()
        if not self._ready.wait(30):
            raise RuntimeError("the pages did not connect")

    async def _page(self, session: aiohttp.ClientSession, connected: list[int]) -> None:
        for path in ("/api/catalog", "/api/tracks"):
            async with session.get(self.url + path) as resp:
                await resp.read()
        async with session.ws_connect(self.url + "/api/ws", headers={"Origin": self.url}) as ws:
            if self.watch_frames:
                await ws.send_str(json.dumps({"type": "frames", "sn": GIMBAL}))
            connected.append(1)
            if len(connected) == self.n:
                self._ready.set()
            assert self._stop is not None
            while not self._stop.is_set():
                try:
                    msg = await ws.receive(timeout=0.5)
                except TimeoutError:
                    continue
                if msg.type != aiohttp.WSMsgType.TEXT:
                    break
                kind = json.loads(msg.data)["type"]  # a page parses every message
                if kind == "state":
                    self.states += 1
                elif kind == "frames":
                    self.frames += 1

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        connected: list[int] = []
        async with aiohttp.ClientSession() as session:
            await asyncio.gather(*(self._page(session, connected) for _ in range(self.n)))

    def close(self) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)


class PageProcess:
    """:class:`Pages` in a process of their own, as a browser is: the gateway's process does only its part."""

    def __init__(self, url: str, n: int, frames: bool = True) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "bench.console", url, str(n), "frames" if frames else "no-frames"],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdout is not None and self.proc.stdin is not None
        if self.proc.stdout.readline().strip() != "ready":
            raise RuntimeError("the pages did not connect")

    @property
    def states(self) -> int:
        assert self.proc.stdout is not None and self.proc.stdin is not None
        self.proc.stdin.write("count\n")
        self.proc.stdin.flush()
        return int(self.proc.stdout.readline().split()[0])

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(15)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


#: the round-trip variants: (label, console on, pages open, whether the page watches the gimbal's frames)
VARIANTS = (
    ("console off", False, 0, False),
    ("console on, no page", True, 0, False),
    ("1 page, no inspector", True, 1, False),
    ("1 page + frame inspector", True, 1, True),
)


def _gateway(broker: LocalBroker, sn: str, console: bool) -> tuple[GatewayThread, Any]:
    """The e2e suite's gateway: one simulated gimbal on a virtual CAN bus, in this process."""
    channel = f"bench-console-{uuid.uuid4().hex[:6]}"
    sim = GimbalCanSim(interface="virtual", channel=channel).start()
    gimbal = {
        "type": "rsdk",
        "sn": GIMBAL,
        "payload_index": "20-0-0",
        "interface": "virtual",
        "channel": channel,
    }
    settings = load_settings(
        None,
        gateway_sn=sn,
        broker={"url": broker.url, "client_id": f"bench-{sn}"},
        dispatcher={"require_authority": False},
        metrics={"port": 0, "enabled": console},
        devices=[gimbal],
    )
    gw = GatewayThread(settings).start()
    deadline = time.monotonic() + 10
    while not gw.app.devices.by_sn(GIMBAL).online and time.monotonic() < deadline:
        time.sleep(0.05)
    return gw, sim


def _round_trips(broker: LocalBroker, n: int, rounds: int) -> dict[str, tuple[list[float], float]]:
    """``x_rsdk_version_get`` round trips per variant, in interleaved rounds, and the page's push rate:
    two of the e2e suite's gateways side by side, one without its HTTP endpoint, one with the console."""
    gateways = {
        False: _gateway(broker, "GW-CONSOLE-OFF", False),
        True: _gateway(broker, "GW-CONSOLE-ON", True),
    }
    try:
        observability = gateways[True][0].app.observability
        assert observability is not None and gateways[False][0].app.observability is None
        url = f"http://127.0.0.1:{observability.port}"
        timers = {
            on: _Timer(broker.port, f"thing/product/{gw.settings.gateway_sn}/services_reply")
            for on, (gw, _) in gateways.items()
        }
        samples: dict[str, list[float]] = {label: [] for label, *_ in VARIANTS}
        rates: dict[str, list[float]] = {label: [] for label, *_ in VARIANTS}
        try:
            # interleaved rounds: a machine whose load changes (others' jobs) weighs on every variant alike
            for _ in range(rounds):
                for label, on, count, frames in VARIANTS:
                    sn = gateways[on][0].settings.gateway_sn
                    pages = PageProcess(url, count, frames) if count else None
                    states = pages.states if pages else 0
                    started = time.monotonic()
                    try:
                        for i in range(n // rounds + 10):
                            tid = f"console-{i}-{uuid.uuid4().hex[:6]}"
                            msg = {
                                "tid": tid,
                                "bid": "bench",
                                "timestamp": 0,
                                "method": "x_rsdk_version_get",
                                "data": {"payload_index": "20-0-0"},
                            }
                            ms = timers[on].round_trip(
                                f"thing/product/{sn}/services", json.dumps(msg).encode(), tid
                            )
                            if i >= 10:
                                samples[label].append(ms)
                    finally:
                        if pages:
                            rates[label].append((pages.states - states) / (time.monotonic() - started))
                            pages.close()
        finally:
            for timer in timers.values():
                timer.close()
        return {label: (samples[label], sum(rates[label]) / max(1, len(rates[label]))) for label in samples}
    finally:
        for gw, sim in gateways.values():
            gw.stop()
            sim.stop()


def run(cfg: Config) -> list[Row]:
    window = 1.0 if cfg.quick else 15.0  # quick: a smoke test inside make test (CPU is its budget)
    n_trips = 50 if cfg.quick else 1000
    rows: list[Row] = []
    with LocalBroker() as broker:
        bare = bare_echo(broker.port, n_trips, warmup=20)
        gateway, url = simulated_gateway(broker.url)
        try:
            time.sleep(1.0 if cfg.quick else 3.0)  # every device online and pushing
            print(f".. console: gateway pid {gateway.proc.pid} at {url}", file=sys.stderr)
            idle_before = _cpu_percent(gateway.proc.pid, window)
            loaded: dict[int, tuple[float, float]] = {}  # pages -> (CPU %, states per second per page)
            for count in (1, 4) if cfg.quick else (1, 20):
                pages = PageProcess(url, count)
                states = pages.states
                cpu = _cpu_percent(gateway.proc.pid, window)
                loaded[count] = (cpu, (pages.states - states) / count / window)
                pages.close()
            idle_after = _cpu_percent(gateway.proc.pid, window)
        finally:
            code = gateway.stop()
        output = gateway.output()
        if code != 0 or "Traceback" in output:
            at = output.find("Traceback")  # the first one, not the shutdown lines after it
            shown = output[-2000:] if at < 0 else output[max(0, at - 500) : at + 3000]
            raise AssertionError(f"the gateway failed (exit {code}): {shown}")
        trips = _round_trips(broker, n_trips, 1 if cfg.quick else 5)
    idle = (idle_before + idle_after) / 2
    rows.append(
        Row(
            group="console",
            case="gateway CPU, no page (%)",
            count=2,
            rate=idle,
            unit="% core",
            note=f"gateway process (3 simulated devices inside it); before {idle_before:.1f} %, after "
            f"{idle_after:.1f} %",
        )
    )
    for count, target in ((1, 5.0), (max(loaded), 15.0)):
        cpu, rate = loaded[count]
        if rate < 5:
            raise AssertionError(f"{count} page(s) got {rate:.1f} states/s each: the push is not running")
        rows.append(
            Row(
                group="console",
                case=f"gateway CPU, {count} page(s) at 10 Hz (%)",
                count=count,
                rate=cpu,
                base_rate=idle,
                max_over_base=target,
                unit="% core",
                note=f"state push + the gimbal's frame inspector; each page got {rate:.1f} states/s",
            )
        )
    off = trips["console off"][0]
    for label, q in (("p50", 0.50), ("p99", 0.99)):
        rows.append(
            Row(
                group="console",
                case=f"x_rsdk_version_get round trip {label}, console off",
                count=n_trips,
                rate=_pct(off, q),
                base_rate=_pct(bare, q),
                base_count=n_trips,
                unit="ms",
                note="the e2e suite's gateway without its HTTP endpoint; baseline: bare broker echo"
                if label == "p50"
                else "",
            )
        )
    for variant, (samples, rate) in trips.items():
        if variant == "console off":
            continue
        for label, q, target in (("p50", 0.50, 1.0), ("p99", 0.99, 3.0)):
            note = ""
            if label == "p50":
                note = f"{variant}" + (f" (another process, {rate:.1f} states/s)" if rate else "")
                note += (
                    "; baseline: the same gateway without its HTTP endpoint, interleaved (the e2e margins)"
                )
            rows.append(
                Row(
                    group="console",
                    case=f"x_rsdk_version_get round trip {label}, {variant}",
                    count=n_trips,
                    rate=_pct(samples, q),
                    base_rate=_pct(off, q),
                    base_count=n_trips,
                    max_over_base=target,
                    unit="ms",
                    note=note,
                )
            )
    return rows


def _serve_pages(url: str, n: int, frames: bool) -> None:
    """The child of :class:`PageProcess`: open the pages, answer "count" on stdin, stop at its end."""
    pages = Pages(url, n, frames)
    print("ready", flush=True)
    for line in sys.stdin:
        if line.strip() == "count":
            print(pages.states, pages.frames, flush=True)
    pages.close()


if __name__ == "__main__":
    _serve_pages(sys.argv[1], int(sys.argv[2]), sys.argv[3] == "frames")
