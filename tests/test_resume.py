"""Fast resume after a broker outage: the gateway probes the broker every ``probe_interval`` (0.5 s by
default) instead of a backoff that grows with the outage, so telemetry and services flow again soon
after the broker returns, whatever the outage lasted. The exact schedule is tested without sleeping
in ``tests/test_broker_link.py``; here a real mosquitto is killed and restarted (``make bench`` measures
2, 6 and 15 s outages: ``bench/resume.py``)."""

from __future__ import annotations

import pytest

from bench.resume import measure

pytestmark = pytest.mark.broker


def test_telemetry_and_services_resume_soon_after_a_6_s_outage() -> None:
    (r,) = measure([6.0], settle=0.5)
    print(f"\nresume after 6 s: telemetry {r.telemetry:.2f} s, fresh osd {r.fresh_telemetry:.2f} s, "
          f"services {r.services:.2f} s, {r.buffered_delivered} buffered osd delivered")  # fmt: skip
    # generous deadlines (a loaded CI machine), still well under what a growing backoff gave (6.5 s)
    assert r.telemetry < 3.0 and r.services < 3.0, r
    assert r.cloud_sessions_lost == 0, r  # the bench's cloud lost its own session: nothing could wait for it
    assert r.buffered_delivered > 0, r  # osd produced during the outage was kept and delivered after it


@pytest.mark.parametrize("bound", ["count", "age"])
def test_telemetry_buffered_in_an_outage_is_bounded_oldest_first(bound: str, can_channel: str) -> None:
    """osd produced while the broker is away waits in a buffer bounded by count and by age; the oldest
    go first and are counted; what is left is delivered after the reconnect, in order."""
    import json
    import time

    import paho.mqtt.client as paho
    from paho.mqtt.enums import CallbackAPIVersion

    from adapters.rsdk.sim import GimbalCanSim
    from gateway.local_broker import LocalBroker
    from gateway.mqtt import close_client
    from tests.support import GatewayThread, gateway_settings, wait_until

    limits = {"telemetry_buffer": 5} if bound == "count" else {"telemetry_buffer_age": 1.0}
    # the cloud's persistent session keeps what arrives while it reconnects too (QoS 0 queued)
    broker = LocalBroker(persistence=True, extra_config="queue_qos0_messages true").start()
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-BUF-1", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(broker.port, [device], osd_period=0.1,
                                broker={"probe_interval": 1.0, "reconnect_min": 1.0, **limits})  # fmt: skip
    got: list[tuple[str, int]] = []
    cloud = paho.Client(
        CallbackAPIVersion.VERSION2, client_id=f"buf-{bound}-{can_channel[-6:]}", clean_session=False
    )
    cloud.reconnect_delay_set(0.02, 0.02)
    cloud.on_connect = lambda c, u, f, rc, p: c.subscribe("thing/product/+/osd", 1)
    cloud.on_message = lambda c, u, m: got.append((m.topic, int(json.loads(m.payload)["timestamp"])))
    cloud.connect("127.0.0.1", broker.port)
    cloud.loop_start()
    gw = GatewayThread(settings).start()
    try:
        wait_until(lambda: len(got) > 5, 10, what="osd flowing")
        metrics = gw.app.metrics
        time.sleep(1.2)  # mosquitto's autosave has the cloud's session on disk
        flushed_before = metrics.count("telemetry_delivered_late_total")  # (osd made before connecting)
        broker.stop(kill=True)
        down_ms = time.time() * 1000
        time.sleep(3.0)
        up_ms = time.time() * 1000  # the gateway reconnects, and flushes its buffer, after this
        broker.start()
        wait_until(lambda: gw.app.bridge.connected, 10, interval=0.002, what="reconnected")
        # osd made before this was buffered or, when this thread noticed the reconnect late (a loaded
        # machine), sent live after it: either way newer than everything the buffer dropped
        back_ms = time.time() * 1000
        wait_until(lambda: metrics.count("telemetry_delivered_late_total") > flushed_before, 10,
                   what="the buffer flushed")  # fmt: skip
        wait_until(lambda: any(ts > back_ms for _, ts in list(got)), 10, what="fresh osd at the cloud")
        late = [(t, ts) for t, ts in list(got) if down_ms < ts < back_ms]
        flushed = metrics.count("telemetry_delivered_late_total") - flushed_before  # what the buffer held
        dropped = metrics.count("telemetry_dropped_total", reason="overflow" if bound == "count" else "age")
        assert dropped > 10, dropped  # ~60 osd produced in 3 s; most were dropped, and counted
        if bound == "count":
            assert 1 <= flushed <= 5, flushed  # the buffer's bound: at most the five newest
            assert len(late) >= flushed, (late, flushed)  # and the cloud got them
        else:  # only what was at most 1 s old at the flush, which came after up_ms
            assert late and min(ts for _, ts in late) > up_ms - 1000 - 500, (late, up_ms)
        # the oldest went first: what was delivered is the end of the outage, not its start
        assert late and min(ts for _, ts in late) > down_ms + 1500, (late, down_ms)
        for topic in {t for t, _ in late}:
            stamps = [ts for t, ts in late if t == topic]
            assert stamps == sorted(stamps)
    finally:
        gw.stop()
        cloud.disconnect()
        cloud.loop_stop()
        close_client(cloud)
        sim.stop()
        broker.stop()
