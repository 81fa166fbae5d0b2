"""How a cloud that follows DJI's device model sees our devices (issue #38, docs/cloud-api.md "Device tree").

The tree is built the way DJI's reference cloud builds it, read in **DJI-Cloud-API-Demo**
``bef525cb94772b06786c1e033719a6fa1b94bcc5``: ``SDKDeviceService.updateTopoOnline`` registers the topic's
serial number as a gateway (with the message's ``domain``/``type``/``sub_type``) and ``sub_devices.get(0)``
as its one child; ``TopologyServiceImpl.getDeviceTopology`` (the list DJI Pilot 2 asks for,
``GET /manage/api/v1/workspaces/{id}/devices/topologies``) gives every gateway in domain 2 (a remote
controller) as a *parent* with its child aircraft as a *host*; docks (domain 3) are listed with their child
(``osdDock``'s ``setChildren``). Payloads are no devices of that tree: DJI reports them inside their
aircraft's osd (``{payload_index}`` keys) and state (``payloads``), per DJI's product-support page ("type,
sub_type and gimbalindex identify a payload and which gimbal port of which aircraft carries it").
"""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from adapters.osdk.sim import OsdkFcDevice
from adapters.rsdk.sim import SlcanGimbal
from adapters.simio import TcpEndpoint
from gateway.cli.run import SIM_AIRCRAFT_SN, SIM_GATEWAY_SN, SIM_GIMBAL_SN, SIM_ROBOT_SN
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, GatewayThread, gateway_settings, simulated_gateway

pytestmark = pytest.mark.broker


@dataclass
class Node:
    sn: str
    domain: str
    key: str  # DJI's device-model key, "{domain}-{type}-{sub_type}"
    gateway: bool = False
    children: list[Node] = field(default_factory=list)  # every sub-device, in the message's order


def dji_tree(statuses: list[tuple[str, dict[str, Any]]]) -> dict[str, Node]:
    """Every device a cloud learns from ``update_topo`` messages (topic's sn, message), the last per topic.

    A gateway is the topic's serial number; its children are its ``sub_devices`` (DJI's reference cloud
    keeps only the first: :func:`pilot_topology` and :func:`docks` read ``children[0]``)."""
    last: dict[str, dict[str, Any]] = {}
    for sn, body in statuses:
        if body.get("method") == "update_topo":
            last[sn] = body["data"]
    nodes: dict[str, Node] = {}
    for sn, data in last.items():
        gw = nodes.setdefault(sn, Node(sn, data["domain"], ""))
        gw.gateway, gw.domain = True, data["domain"]
        gw.key = f"{data['domain']}-{data['type']}-{data['sub_type']}"
        gw.children = []
        for d in data["sub_devices"]:
            child = nodes[d["sn"]] if d["sn"] in nodes else Node(d["sn"], d["domain"], "")
            child.domain, child.key = d["domain"], f"{d['domain']}-{d['type']}-{d['sub_type']}"
            nodes[d["sn"]] = child
            gw.children.append(child)
    return nodes


def pilot_topology(nodes: dict[str, Node]) -> list[tuple[str, list[str]]]:
    """DJI Pilot 2's topology list: (remote controller, [its aircraft]) for every gateway in domain 2."""
    return [
        (n.sn, [c.sn for c in n.children[:1] if c.domain == "0"])
        for n in nodes.values()
        if n.gateway and n.domain == "2"
    ]


def docks(nodes: dict[str, Node]) -> dict[str, str | None]:
    """Docks and the aircraft DJI's reference cloud takes as each one's child (``sub_devices[0]``)."""
    return {
        n.sn: (n.children[0].sn if n.children and n.children[0].domain == "0" else None)
        for n in nodes.values()
        if n.gateway and n.domain == "3"
    }


def _statuses(cloud: CloudClient) -> list[tuple[str, dict[str, Any]]]:
    return [
        (t.split("/")[2], b) for t, b, _ in list(cloud.messages) if t.endswith("/status") and b is not None
    ]


# ------------------------------------------------------------------------------------- run --simulate
@pytest.fixture(scope="module")
def simulated() -> Iterator[tuple[CloudClient, Any]]:
    with LocalBroker() as broker:
        proc, _ = simulated_gateway(broker.url)
        cloud = CloudClient(broker.host, broker.port, SIM_GATEWAY_SN)
        try:
            yield cloud, proc
            # a clean stop announces the robot offline on its own topic too (the MQTT will covers only the
            # gateway's): checked here, where the module's gateway ends, not in a test that would end it
            cloud.clear()
            assert proc.stop() == 0, proc.output()[-2000:]
            cloud.wait_for(f"{SIM_ROBOT_SN}/status", lambda b: b["data"]["sub_devices"] == [], timeout=5)
            cloud.wait_for(f"{SIM_GATEWAY_SN}/status", lambda b: b["data"]["sub_devices"] == [], timeout=5)
        finally:
            cloud.close()
            proc.stop()


def test_the_simulated_devices_land_where_djis_model_puts_them(simulated: tuple[CloudClient, Any]) -> None:
    """The dock with its aircraft; the robot its own gateway in a domain no DJI device claims; the stand-alone
    gimbal a payload listed after the aircraft; nothing a remote controller."""
    cloud, _ = simulated
    cloud.wait_for(f"{SIM_GATEWAY_SN}/status", lambda b: len(b["data"]["sub_devices"]) == 2, timeout=20)
    cloud.wait_for(f"{SIM_ROBOT_SN}/status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=20)
    nodes = dji_tree(_statuses(cloud))

    assert docks(nodes) == {SIM_GATEWAY_SN: SIM_AIRCRAFT_SN}  # the dock and its aircraft, first in its list
    dock = nodes[SIM_GATEWAY_SN]
    assert dock.key == "3-1-0" and [c.sn for c in dock.children] == [SIM_AIRCRAFT_SN, SIM_GIMBAL_SN]
    assert nodes[SIM_AIRCRAFT_SN].key == "0-60-0"
    assert nodes[SIM_GIMBAL_SN].domain == "1" and not nodes[SIM_GIMBAL_SN].gateway  # a stand-alone payload
    robot = nodes[SIM_ROBOT_SN]
    assert robot.gateway and robot.key == "100-1-0" and [c.sn for c in robot.children] == [SIM_ROBOT_SN]
    assert robot not in dock.children
    # Pilot 2's list of remote controllers and their aircraft: none (the robot used to be one, 2-56-0)
    assert pilot_topology(nodes) == []
    assert all(n.domain != "2" for n in nodes.values())


def test_the_robot_answers_on_its_own_topic_and_refuses_what_belongs_to_the_dock(
    simulated: tuple[CloudClient, Any],
) -> None:
    """A cloud that reads the robot as a gateway sends it services on its own topic: served there, answered
    there with its own serial number; a dock's method is refused naming the gateway to ask."""
    cloud, _ = simulated
    cloud.wait_for(f"{SIM_ROBOT_SN}/status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=20)
    stop = _service_on(cloud, SIM_ROBOT_SN, "x_robomaster_stop", {})
    assert stop["gateway"] == SIM_ROBOT_SN and stop["data"]["result"] == 0, stop
    home = _service_on(cloud, SIM_ROBOT_SN, "return_home", {})
    assert home["data"]["result"] == 399001, home
    assert SIM_GATEWAY_SN in home["data"]["output"]["reason"]
    wrong = _service_on(cloud, SIM_ROBOT_SN, "x_robomaster_stop", {"sn": SIM_AIRCRAFT_SN})
    assert wrong["data"]["result"] != 0, wrong
    # the same method on the dock's topic still reaches the robot (by sn), answered on the dock's topic
    again = cloud.service("x_robomaster_stop", {"sn": SIM_ROBOT_SN})
    assert again["gateway"] == SIM_GATEWAY_SN and again["data"]["result"] == 0, again


def _service_on(cloud: CloudClient, sn: str, method: str, data: dict[str, Any]) -> dict[str, Any]:
    import json

    tid = str(uuid.uuid4())
    message = {"tid": tid, "bid": str(uuid.uuid4()), "timestamp": 1, "method": method, "data": data}
    cloud.publish(f"thing/product/{sn}/services", json.dumps(message))
    return cloud.wait_for(f"{sn}/services_reply", lambda b: b.get("tid") == tid, timeout=10)[-1]


# ------------------------------------------------------------------------------- a gimbal on an aircraft
def test_a_carried_gimbal_is_reported_inside_its_aircraft(broker: LocalBroker) -> None:
    """``carried_by``: the gimbal is no device of the tree; its angles are a ``{payload_index}`` key of the
    aircraft's osd, it is a line of the aircraft's ``payloads`` state, and its methods still reach it."""
    gimbal, fc = TcpEndpoint(SlcanGimbal()).start(), TcpEndpoint(OsdkFcDevice()).start()
    devices: list[dict[str, Any]] = [
        {"type": "rsdk", "sn": "RS-ON-1", "interface": "slcan", "channel": gimbal.url,
         "bus_options": {"sleep_after_open": 0}, "carried_by": "FC-1"},
        {"type": "osdk", "sn": "FC-1", "url": fc.url},
    ]  # fmt: skip
    cloud = CloudClient(broker.host, broker.port, "GW-TREE-1")
    gw = GatewayThread(gateway_settings(broker.port, devices, gateway_sn="GW-TREE-1")).start()
    try:
        cloud.wait_for("GW-TREE-1/status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=15)
        osd = cloud.wait_for("FC-1/osd", lambda b: "20-0-0" in b["data"], timeout=10)[-1]["data"]
        assert osd["20-0-0"]["payload_index"] == "20-0-0" and "gimbal_pitch" in osd["20-0-0"], osd
        state = cloud.wait_for(
            "FC-1/state", lambda b: any(p["sn"] == "RS-ON-1" for p in b["data"].get("payloads") or [])
        )[-1]["data"]
        assert {"payload_index": "20-0-0", "sn": "RS-ON-1", "control_source": ""} in state["payloads"]
        nodes = dji_tree(_statuses(cloud))
        assert docks(nodes) == {"GW-TREE-1": "FC-1"} and "RS-ON-1" not in nodes
        assert cloud.find("RS-ON-1/") == []  # it publishes nothing under its own serial number
        # still the gimbal's methods: grab, then a photo through its payload index
        assert cloud.service("payload_authority_grab", {"payload_index": "20-0-0"})["data"]["result"] == 0
        held = {"payload_index": "20-0-0", "sn": "RS-ON-1", "control_source": "A"}
        cloud.wait_for("FC-1/state", lambda b: held in (b["data"].get("payloads") or []))
        assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 0
    finally:
        gw.stop()
        cloud.close()
        gimbal.stop()
        fc.stop()
