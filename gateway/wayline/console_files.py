"""``dji-gateway send flighttask_prepare file=route.kmz …``: the console serves a local KMZ itself and
fills in what a cloud would (``file.url``, ``file.fingerprint`` = lowercase MD5, a ``flight_id``,
``task_type`` 0 and an ``execute_time`` of now when not given).

Owns a one-file HTTP server on 127.0.0.1 (a thread of the console process, never of the gateway) that
lives until the prepare is answered: the gateway downloads the file during the prepare. Knows nothing
of MQTT. ``dji-gateway route-demo PATH`` writes the KMZ of the README's "fly a route" walkthrough.
Time: the console's own (the system clock): a process of its own, not the gateway's injected clock.
"""

from __future__ import annotations

import argparse
import threading
import time
import uuid
from pathlib import Path
from typing import Any

__all__ = ["ServedFile", "add_parsers", "demo_kmz", "serve_prepare_fields"]


class ServedFile:
    """One file at ``http://127.0.0.1:PORT/NAME`` until :meth:`close`."""

    def __init__(self, data: bytes, name: str, host: str = "127.0.0.1") -> None:
        from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer  # only when serving a file

        body = data

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                if self.path.split("?")[0] != f"/{name}":
                    self.send_response(404)
                    self.end_headers()
                    return
                self.send_response(200)
                self.send_header("Content-Type", "application/vnd.google-earth.kmz")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer((host, 0), Handler)
        self.url = f"http://{host}:{self.server.server_port}/{name}"
        self.thread = threading.Thread(target=self.server.serve_forever, name="kmz-file", daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def serve_prepare_fields(fields: list[str]) -> tuple[list[str], ServedFile | None]:
    """``fields`` with ``file=PATH`` replaced by the served URL and its fingerprint (and the defaults a
    cloud fills in); ``(fields, None)`` when there is no ``file=``. OSError when PATH cannot be read."""
    paths = [f.partition("=")[2] for f in fields if f.startswith("file=")]
    if not paths:
        return fields, None
    from adapters.wayline.writer import md5_hex

    path = Path(paths[-1])
    data = path.read_bytes()
    served = ServedFile(data, path.name.replace("/", "_") or "route.kmz")
    out = [f for f in fields if not f.startswith("file=")]
    names = {f.partition("=")[0] for f in out}
    out += [f"file.url={served.url}", f"file.fingerprint={md5_hex(data)}"]
    if "flight_id" not in names:
        out.append(f"flight_id={uuid.uuid4()}")
    if "task_type" not in names:
        out.append("task_type=0")
    if "execute_time" not in names:
        out.append(f"execute_time={int(time.time() * 1000)}")
    return out, served


#: The simulator's home (adapters.osdk.sim.DEFAULT_HOME) and a 3-waypoint route 40 m north and east of it.
DEMO_HOME = (22.5431, 113.958)


def demo_kmz(height: float = 30.0) -> bytes:
    """A 3-waypoint route around the simulator's home, heights relative to the take-off point, a
    gimbalRotate (-45°) and a takePhoto at waypoint 1."""
    import math

    from adapters.wayline.writer import ActionSpec, PointSpec, kmz_bytes, waylines_wpml

    def at(north: float, east: float) -> tuple[float, float]:
        lat = DEMO_HOME[0] + math.degrees(north / 6_378_137.0)
        return lat, DEMO_HOME[1] + math.degrees(east / (6_378_137.0 * math.cos(math.radians(DEMO_HOME[0]))))

    actions = [
        ActionSpec("gimbalRotate", {"gimbalRotateMode": "absoluteAngle", "gimbalPitchRotateEnable": 1,
                                    "gimbalPitchRotateAngle": -45}),
        ActionSpec("takePhoto", {"fileSuffix": "wp1", "payloadPositionIndex": 0}),
    ]  # fmt: skip
    points = [PointSpec(*at(0, 0), height), PointSpec(*at(40, 0), height, actions=actions),
              PointSpec(*at(40, 40), height)]  # fmt: skip
    return kmz_bytes(waylines_wpml(points, speed=8.0, take_off_security_height=10.0))


def _cmd_route_demo(ns: argparse.Namespace) -> int:
    from adapters.wayline.writer import md5_hex

    data = demo_kmz(ns.height)
    Path(ns.path).write_bytes(data)
    print(f"wrote {ns.path} ({len(data)} bytes, md5 {md5_hex(data)})")
    return 0


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "route-demo",
        help="write a 3-waypoint wayline KMZ around the simulator's home",
        description="Write the KMZ of the README's 'fly a route' walkthrough: 3 waypoints around the "
        "simulated aircraft's home, heights relative to the take-off point, gimbalRotate and takePhoto at "
        "waypoint 1. Send it with: dji-gateway send flighttask_prepare file=PATH",
    )
    p.add_argument("path", help="where to write the KMZ, e.g. route.kmz")
    p.add_argument("--height", type=float, default=30.0, help="height above the take-off point (m), 30")
    p.set_defaults(handler=_cmd_route_demo)
