"""No private attribute of a library (paho-mqtt, aiohttp, python-can, pyserial) is touched outside the one
documented wrapper, and the internals that wrapper and python-can's virtual-bus fast path rely on are
still where they were read: a new library release that moves them fails here, not in the field."""

from __future__ import annotations

import ast
import asyncio
import importlib.metadata
import inspect
import queue
import uuid
from pathlib import Path

import aiohttp.web
import can
import paho.mqtt.client as paho
import serial
from can.interfaces import virtual

from adapters.rsdk import link
from gateway import pahocompat

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("schemas", "adapters", "gateway")
#: the one module allowed to reach a library's private member (it says which, and why)
WRAPPERS = {ROOT / "gateway" / "pahocompat.py"}
LIBRARY_CLASSES: tuple[type, ...] = (
    paho.Client,
    paho.MQTTMessage,
    paho.MQTTMessageInfo,
    aiohttp.web.Application,
    aiohttp.web.AppRunner,
    aiohttp.web.TCPSite,
    aiohttp.web.SockSite,
    aiohttp.web.Request,
    aiohttp.web.WebSocketResponse,
    aiohttp.ClientSession,
    can.BusABC,
    virtual.VirtualBus,
    can.Notifier,
    can.Message,
    serial.Serial,
    serial.SerialBase,
)


def _private_names(cls: type) -> set[str]:
    names = {n for n in dir(cls) if n.startswith("_") and not n.startswith("__")}
    # instance attributes set in __init__ (self._x = ...) are not in dir(cls): read them from the source
    for klass in cls.__mro__:
        try:
            tree = ast.parse(inspect.getsource(klass))
        except (OSError, TypeError, SyntaxError, IndentationError):
            continue
        for node in ast.walk(tree):
            if (
                (
                    isinstance(node, ast.Attribute)
                    and isinstance(node.value, ast.Name)
                    and node.value.id == "self"
                )
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
            ):
                names.add(node.attr)
    return names


def _library_private_names() -> set[str]:
    names: set[str] = set()
    for cls in LIBRARY_CLASSES:
        names |= _private_names(cls)
    names.add("_socket")  # paho's websocket wrapper
    return names


def _offenders(paths: list[Path], private: set[str], root: Path = ROOT) -> list[str]:
    """``x._name`` (``x`` not ``self``/``cls``/``super()``) and ``getattr(x, "_name")`` where ``_name`` is a
    library's private member name."""
    found: list[str] = []
    for path in paths:
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            name: str | None = None
            if isinstance(node, ast.Attribute) and node.attr in private:
                base = node.value
                if isinstance(base, ast.Name) and base.id in ("self", "cls"):
                    continue
                if isinstance(base, ast.Call) and isinstance(base.func, ast.Name) and base.func.id == "super":
                    continue
                name = node.attr
            elif (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Name)
                and node.func.id in ("getattr", "setattr", "hasattr")
                and len(node.args) >= 2
                and isinstance(node.args[1], ast.Constant)
                and node.args[1].value in private
            ):
                name = str(node.args[1].value)
            if name is not None:
                found.append(f"{path.relative_to(root)}:{node.lineno}: {ast.unparse(node)}")
    return found


def _package_files() -> list[Path]:
    return [p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py")) if p not in WRAPPERS]


def test_no_library_private_attribute_outside_the_wrapper() -> None:
    private = _library_private_names()
    assert {"_reset_sockets", "_sock_close", "_thread", "_server", "_open"} <= private
    assert _offenders(_package_files(), private) == []


def test_the_scan_catches_private_access(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text(
        "def f(client, site, bus):\n"
        "    client._thread = None\n"
        "    s = site._server\n"
        "    if not bus._open: pass\n"
        "    return getattr(client, '_sock_close')\n"
        "class C:\n"
        "    def g(self):\n"
        "        return self._thread, super()._open\n"
    )
    found = _offenders([bad], _library_private_names(), root=tmp_path)
    assert sorted(line.split(":")[1] for line in found) == ["2", "3", "4", "5"], found


# -- paho: the wrapper's two private members ------------------------------------------------------------


def test_paho_internals_the_wrapper_uses_are_still_there() -> None:
    version = importlib.metadata.version("paho-mqtt")
    assert version.rsplit(".", version.count(".") - 1)[0] in pahocompat.CHECKED, (
        f"paho-mqtt {version} was not checked: read gateway/pahocompat.py against it, then add it to CHECKED"
    )
    assert pahocompat.private_members_present() == []


def test_release_sockets_closes_what_loop_start_opened() -> None:
    client = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id=f"probe-{uuid.uuid4().hex[:6]}")
    client.loop_start()
    client.loop_stop()
    pair = [s for s in vars(client).values() if hasattr(s, "fileno") and hasattr(s, "recv")]
    assert pair, "loop_start made no wake-up socket pair"
    pahocompat.release_sockets(client)
    assert all(s.fileno() == -1 for s in pair)  # closed


# -- python-can: the virtual bus layout the fast path reads -------------------------------------------


def test_python_can_virtual_bus_layout_is_still_the_one_read() -> None:
    version = can.__version__
    assert version.rsplit(".", version.count(".") - 1)[0] in link.VIRTUAL_LAYOUT_CHECKED, (
        f"python-can {version} was not checked: read adapters/rsdk/link.py against it, then add it"
    )
    channel = f"djigw-internals-{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    other = can.Bus(interface="virtual", channel=channel)
    try:
        for name in link.VIRTUAL_BUS_ATTRIBUTES:
            assert hasattr(bus, name), name
        assert isinstance(getattr(virtual, "channels_lock", None), type(virtual.channels_lock))
        assert isinstance(bus.queue, queue.Queue) and bus.queue in bus.channel  # type: ignore[attr-defined]
        reader = link.virtual_reader(other)
        send = link.virtual_sender(bus)
        assert reader is not None and send is not None, "the fast path turned itself off"
        send(can.Message(arbitration_id=0x223, data=b"\x01\x02", is_extended_id=False))
        got = other.recv(1.0)
        assert got is not None and bytes(got.data) == b"\x01\x02" and got.is_rx
    finally:
        other.shutdown()
        bus.shutdown()
    # a bus that was shut down refuses to send, as python-can's own send does
    try:
        send(can.Message(arbitration_id=0x223, data=b"\x03"))
    except can.CanOperationError:
        pass
    else:
        raise AssertionError("a closed virtual bus accepted a frame")
    if reader is not None and reader.close is not None:
        reader.close()


# -- aiohttp: the bound port comes from the public runner.addresses -------------------------------------


def test_aiohttp_runner_addresses_gives_the_bound_port() -> None:
    async def bind() -> tuple[str, int]:
        runner = aiohttp.web.AppRunner(aiohttp.web.Application())
        await runner.setup()
        try:
            site = aiohttp.web.TCPSite(runner, "127.0.0.1", 0)
            await site.start()
            (address,) = runner.addresses
            return str(address[0]), int(address[1])
        finally:
            await runner.cleanup()

    host, port = asyncio.run(bind())
    assert host == "127.0.0.1" and port > 0
