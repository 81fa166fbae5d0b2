"""Fuzzing every inbound path: random bytes, random JSON, mutated valid messages, huge and deeply nested
payloads, NaN/Inf, unicode serial numbers — on every topic the gateway subscribes to, straight into the
real dispatcher and the DRC handler (no broker needed: these are the functions the MQTT thread calls).

Properties: nothing raises out of a handler; nothing is counted as an internal error; a services message
whose tid, bid and method can be read gets exactly one reply carrying that tid."""

from __future__ import annotations

import asyncio
import json
import re

from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.clock import SystemClock
from gateway.devices import DeviceTable
from gateway.dispatcher import Dispatcher
from gateway.metrics import Metrics
from gateway.settings import DispatcherSettings
from schemas import TopicKind, subscriptions, topic
from schemas.examples import SEED_003
from tests import fuzz_stats
from tests.support import FakeAdapter

GW = "GW-FUZZ-1"


class EchoAdapter(FakeAdapter):
    """A device that does every camera/gimbal method at once (the dispatcher is what is fuzzed)."""

    def __init__(self) -> None:
        methods = ("camera_photo_take", "camera_aim", "camera_screen_drag", "gimbal_reset",
                   "camera_mode_switch", "camera_recording_start", "camera_recording_stop")  # fmt: skip
        super().__init__("FUZZ-DEV", "39-0-7", {m: self.ok for m in methods})


class Recorder:
    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes]] = []

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        self.sent.append((topic, payload))
        return True


def _dispatcher() -> tuple[Dispatcher, Recorder, Metrics]:
    from gateway.app import build_registry

    out, metrics = Recorder(), Metrics()
    devices = DeviceTable([EchoAdapter()])
    devices.authority.payloads.add("39-0-7")
    d = Dispatcher(
        gateway_sn=GW,
        registry=build_registry(),
        devices=devices,
        outbox=out,
        settings=DispatcherSettings(reply_cache_seconds=0),
        clock=SystemClock(),
        metrics=metrics,
    )
    return d, out, metrics


TOPICS = [*subscriptions(GW), topic(TopicKind.SERVICES, "OTHER"), "thing/product/x/y/z", "", "a/b"]
SEED_SERVICES = [json.loads(e.text) for e in SEED_003 if e.kind is TopicKind.SERVICES]

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=30),
    lambda children: (
        st.lists(children, max_size=5) | st.dictionaries(st.text(max_size=12), children, max_size=5)
    ),
    max_leaves=30,
)


@st.composite
def mutated(draw: st.DrawFn) -> bytes:
    """A seed example with one part replaced by something else (or deleted)."""
    msg = json.loads(json.dumps(draw(st.sampled_from(SEED_SERVICES))))
    target = draw(st.sampled_from(["envelope", "data"]))
    node = msg if target == "envelope" or not isinstance(msg.get("data"), dict) else msg["data"]
    if node:
        key = draw(st.sampled_from(sorted(node)))
        if draw(st.booleans()):
            node[key] = draw(json_values)
        else:
            del node[key]
    node[draw(st.text(max_size=8))] = draw(json_values)
    return json.dumps(msg, allow_nan=True).encode()


def _with_gateway_sn(sn: str) -> bytes:
    """Unicode (and worse) in the envelope's serial number."""
    msg = {
        "tid": "t",
        "bid": "b",
        "gateway": sn,
        "method": "camera_photo_take",
        "data": {"payload_index": "39-0-7"},
    }
    return json.dumps(msg).encode()


payloads = st.one_of(
    st.binary(max_size=300),
    json_values.map(lambda v: json.dumps(v, allow_nan=True).encode()),
    mutated(),
    st.integers(1, 5000).map(
        lambda n: b'{"tid":"t","bid":"b","method":"camera_aim","data":' + b"[" * n + b"]" * n + b"}"
    ),
    st.text(max_size=40).map(_with_gateway_sn),
)


def _readable(payload: bytes) -> str | None:
    try:
        msg = json.loads(payload)
    except (ValueError, UnicodeDecodeError, RecursionError):
        return None
    if not isinstance(msg, dict):
        return None
    tid, bid, method = msg.get("tid"), msg.get("bid"), msg.get("method")
    ok = all(isinstance(v, str) and 0 < len(v) <= 128 for v in (tid, bid)) and isinstance(method, str)
    ok = ok and re.fullmatch(r"[a-z][a-z0-9_]{0,63}", method) is not None
    return tid if ok else None


@settings(max_examples=600)
@given(st.sampled_from(TOPICS), payloads)
def test_dispatcher_survives_anything(topic_name: str, payload: bytes) -> None:
    d, out, metrics = _dispatcher()
    asyncio.run(d.handle(topic_name, payload, oversize=len(payload) > 65536))
    fuzz_stats.count("dispatcher")
    assert metrics.count("handler_exceptions_total") == 0
    if topic_name == topic(TopicKind.SERVICES, GW):
        tid = _readable(payload)
        if tid is not None:
            replies = [json.loads(p) for t, p in out.sent if t.endswith("/services_reply")]
            assert [r["tid"] for r in replies] == [tid]
            assert replies[0]["data"]["result"] == 0 or 300000 <= replies[0]["data"]["result"] <= 599999
    for _, raw in out.sent:  # whatever goes out is valid JSON without NaN
        json.loads(raw, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))


@settings(max_examples=300)
@given(payloads)
def test_drc_handler_survives_anything(payload: bytes) -> None:
    from gateway.app import build_registry
    from gateway.drc import DrcController
    from tests.support import gateway_settings, live_drc_session

    sent: list[bytes] = []

    class Up:
        def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
            sent.append(payload)
            return True

    loop = asyncio.new_event_loop()
    try:
        drc = DrcController(
            settings=gateway_settings(1, [], gateway_sn=GW),
            registry=build_registry(),
            devices=DeviceTable([EchoAdapter()]),
            metrics=Metrics(),
            loop=loop,
            main_bridge=Up(),  # type: ignore[arg-type]
            publish_event=lambda *a: None,
            publish_gateway_osd=lambda d: None,
        )
        sid = live_drc_session(drc)
        drc.handle_down(payload, sid, Up())  # type: ignore[arg-type]
    finally:
        loop.close()
    fuzz_stats.count("drc")
    for raw in sent:
        json.loads(raw)
