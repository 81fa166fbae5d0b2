"""Real clouds' request shapes end to end (issue #17, the contract half): ``dji-gateway run --simulate`` as
its own process, a real mosquitto, and requests published exactly as DJI's Java Cloud SDK writes them
(schemas.examples.CLOUD_SHAPES: ``"data": ""`` for methods without parameters, ``60.0`` for integer
fields, the Cloud API 1.x take-off fields)."""

from __future__ import annotations

import json
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from gateway.cli.run import SIM_AIRCRAFT_SN, SIM_GATEWAY_SN
from gateway.local_broker import LocalBroker
from schemas.examples import CLOUD_SHAPES
from tests.support import CloudClient, simulated_gateway

pytestmark = pytest.mark.broker


@pytest.fixture(scope="module")
def simulated() -> Iterator[CloudClient]:
    with LocalBroker() as broker:
        proc, _ = simulated_gateway(broker.url)
        cloud = CloudClient(broker.host, broker.port, SIM_GATEWAY_SN)
        try:
            cloud.wait_for(f"{SIM_AIRCRAFT_SN}/osd", lambda b: "latitude" in b["data"], timeout=20)
            yield cloud
        finally:
            cloud.close()
            proc.stop()


def _as_sent(cloud: CloudClient, method: str, **data: Any) -> dict[str, Any]:
    """Publish the CLOUD_SHAPES request of ``method`` as its text says (floats stay floats: json writes
    60.0 as 60.0), with a fresh tid and ``data`` keys replaced when given; return the reply."""
    shape = next(s for s in CLOUD_SHAPES if s.method == method and s.text.count('"data": ""') == 0)
    message = json.loads(shape.text)
    message["data"] = {**message["data"], **data}
    return _publish(cloud, message)


def _publish(cloud: CloudClient, message: dict[str, Any]) -> dict[str, Any]:
    tid = message["tid"] = str(uuid.uuid4())
    cloud.publish(f"thing/product/{SIM_GATEWAY_SN}/services", json.dumps(message))
    return cloud.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=10)[-1]


def test_java_sdk_shapes_are_answered_and_the_aircraft_climbs(simulated: CloudClient) -> None:
    cloud = simulated
    grab = next(s for s in CLOUD_SHAPES if s.method == "flight_authority_grab" and '"data": ""' in s.text)
    message = json.loads(grab.text)
    assert message["data"] == ""
    reply = _publish(cloud, message)
    assert reply["data"]["result"] == 0, reply

    home = cloud.wait_for(f"{SIM_AIRCRAFT_SN}/osd", lambda b: "latitude" in b["data"])[-1]["data"]
    reply = _as_sent(
        cloud,
        "takeoff_to_point",
        target_latitude=home["latitude"] + 0.0003,
        target_longitude=home["longitude"],
        target_height=home["height"] + 40.0,  # WGS84: 40 m above the take-off point
    )
    assert reply["data"]["result"] == 0, reply
    text = next(s.text for s in CLOUD_SHAPES if s.method == "takeoff_to_point")
    assert '"rth_altitude": 60.0' in text and '"target_height": 90.0' in text and '"rth_mode": 1' in text
    cloud.wait_for(f"{SIM_AIRCRAFT_SN}/osd", lambda b: b["data"].get("elevation", 0.0) > 25.0, timeout=30)

    for method in ("fly_to_point_stop", "drc_mode_exit"):
        shape = next(s for s in CLOUD_SHAPES if s.method == method)
        message = json.loads(shape.text)
        assert message["data"] == ""
        reply = _publish(cloud, message)
        reason = (reply["data"].get("output") or {}).get("reason", "")
        assert not reason.startswith("data"), reply  # no parse error: the method itself answered
