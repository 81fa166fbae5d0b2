"""Network namespaces for the cellular-link tests and benchmarks: the gateway in a namespace of its own,
joined to the broker's (the host's) by a veth pair the test makes, impaired by ``tc netem`` where the
kernel has it, else by the userspace relay ``tests/linkemu.py``; partitions by ``ip link set … down``
on the veth (real kernel behaviour: TCP retransmits into the void, nobody sends a reset).

Owns the namespace, the veth pair, their addresses (10.253.K.0/30, K random, only inside the pair the
test made: the host end 10.253.K.1, the gateway end 10.253.K.2) and their removal; and
:func:`enter_netns`, which moves the calling *thread* into the namespace (``setns`` is per thread;
threads it starts later inherit it), so an in-process gateway runs there while the test, the cloud
and the broker stay on the host. Needs root and iproute2; :func:`netns_problem` and
:func:`netem_problem` say why not, for ``pytest.skip``.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import random
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

from gateway.local_broker import port_open

__all__ = ["LinkEmulator", "VethLink", "enter_netns", "netem_problem", "netns_problem"]

CLONE_NEWNET = 0x40000000
ROOT = Path(__file__).resolve().parents[1]


def _ip(*args: str, ns: str | None = None, check: bool = True) -> subprocess.CompletedProcess[str]:
    cmd = ["ip", *(["-n", ns] if ns else []), *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=30, check=check)


def _tc(*args: str, ns: str | None = None) -> subprocess.CompletedProcess[str]:
    prefix = ["ip", "netns", "exec", ns] if ns else []
    return subprocess.run([*prefix, "tc", *args], capture_output=True, text=True, timeout=30)


@functools.cache
def netns_problem() -> str | None:
    """Why network namespaces cannot be used here (None when they can): made and removed once to see."""
    if sys.platform != "linux":
        return "network namespaces are Linux only"
    if os.geteuid() != 0:
        return "making network namespaces needs root"
    if shutil.which("ip") is None:
        return "iproute2 ('ip') is not installed"
    try:
        with VethLink():
            pass
    except (OSError, subprocess.SubprocessError, RuntimeError) as exc:
        return f"cannot make a namespace and a veth pair here: {exc}"
    return None


@functools.cache
def netem_problem() -> str | None:
    """Why ``tc netem`` cannot be used (None when it can); netns_problem() first."""
    problem = netns_problem()
    if problem is not None:
        return problem
    if shutil.which("tc") is None:
        return "tc (iproute2) is not installed"
    with VethLink() as link:
        out = _tc("qdisc", "add", "dev", link.host_if, "root", "netem", "delay", "1ms")
        if out.returncode != 0:
            return f"the kernel has no netem qdisc (sch_netem): tc said {out.stderr.strip()!r}"
    return None


def enter_netns(name: str) -> None:
    """Move the calling thread into network namespace ``name``."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    fd = os.open(f"/var/run/netns/{name}", os.O_RDONLY)
    try:
        if libc.setns(fd, CLONE_NEWNET) != 0:
            err = ctypes.get_errno()
            raise OSError(err, f"setns({name}): {os.strerror(err)}")
    finally:
        os.close(fd)


class VethLink:
    """A namespace for the gateway and a veth pair to the host, made on enter, removed on exit."""

    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:8]
        self.ns = f"djigw-{tag}"
        self.host_if = f"vh{tag}"
        self.gw_if = f"vg{tag}"
        used = _ip("-4", "-o", "addr", "show", check=False).stdout
        free = [k for k in range(256) if f"10.253.{k}." not in used]  # another run's pair keeps its own
        self.k = random.choice(free or [random.randrange(0, 256)])
        self.host_ip = f"10.253.{self.k}.1"
        self.gw_ip = f"10.253.{self.k}.2"
        self._made = False

    def __enter__(self) -> VethLink:
        try:
            _ip("netns", "add", self.ns)
            self._made = True
            _ip("link", "add", self.host_if, "type", "veth", "peer", "name", self.gw_if)
            _ip("link", "set", self.gw_if, "netns", self.ns)
            _ip("addr", "add", f"{self.host_ip}/30", "dev", self.host_if)
            _ip("link", "set", self.host_if, "up")
            _ip("addr", "add", f"{self.gw_ip}/30", "dev", self.gw_if, ns=self.ns)
            _ip("link", "set", self.gw_if, "up", ns=self.ns)
            _ip("link", "set", "lo", "up", ns=self.ns)
            # fixed neighbours: a cellular interface (raw IP, PPP) has no ARP, and an ARP entry that went
            # FAILED during a partition would add its own re-resolution delay to every figure
            host_mac, gw_mac = self._mac(self.host_if, None), self._mac(self.gw_if, self.ns)
            _ip("neigh", "replace", self.gw_ip, "lladdr", gw_mac, "dev", self.host_if, "nud", "permanent")
            _ip("neigh", "replace", self.host_ip, "lladdr", host_mac, "dev", self.gw_if, "nud", "permanent",
                ns=self.ns)  # fmt: skip
        except subprocess.CalledProcessError as exc:
            self.__exit__()
            raise RuntimeError(f"{' '.join(exc.cmd)}: {exc.stderr.strip()}") from None
        return self

    @staticmethod
    def _mac(dev: str, ns: str | None) -> str:
        out = _ip("-o", "link", "show", dev, ns=ns).stdout
        return out.split("link/ether", 1)[1].split()[0]

    def __exit__(self, *exc: object) -> None:
        _ip("link", "del", self.host_if, check=False)  # removes both ends
        if self._made:
            _ip("netns", "del", self.ns, check=False)
            self._made = False

    # -- impairments ------------------------------------------------------------------------------
    def netem(self, delay_ms: float, jitter_ms: float, loss: float) -> None:
        """Each direction: ``delay ± jitter`` and ``loss`` (a fraction), with tc netem on both ends."""
        for ns, dev in ((None, self.host_if), (self.ns, self.gw_if)):
            spec = [
                "delay",
                f"{delay_ms}ms",
                f"{jitter_ms}ms",
                "distribution",
                "normal",
                "loss",
                f"{loss * 100}%",
            ]
            out = _tc("qdisc", "replace", "dev", dev, "root", "netem", *spec, ns=ns)
            if out.returncode != 0:
                raise RuntimeError(f"tc netem on {dev}: {out.stderr.strip()}")

    def down(self) -> None:
        """A partition: the host end goes down, the gateway's end stays up with no carrier (as a modem
        that has lost the network: its packets go nowhere, no reset comes back)."""
        _ip("link", "set", self.host_if, "down")

    def up(self) -> None:
        _ip("link", "set", self.host_if, "up")
        # the connected route comes back with the link; wait until the kernel uses it again
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            out = _ip("route", "get", self.gw_ip, check=False)
            if self.host_if in out.stdout:
                return
            time.sleep(0.01)


class LinkEmulator:
    """``tests/linkemu.py`` as its own process on the host: listens on ``listen`` (the host end of the
    veth) and relays to ``to`` (the broker) with the given delay, jitter and loss."""

    def __init__(self, listen: tuple[str, int], to: tuple[str, int], *, delay_ms: float, jitter_ms: float,
                 loss: float, seed: int | None = None) -> None:  # fmt: skip
        self.listen, self.to = listen, to
        args = [sys.executable, "-m", "tests.linkemu", "--listen", f"{listen[0]}:{listen[1]}",
                "--to", f"{to[0]}:{to[1]}", "--delay-ms", str(delay_ms), "--jitter-ms", str(jitter_ms),
                "--loss", str(loss)]  # fmt: skip
        if seed is not None:
            args += ["--seed", str(seed)]
        self._proc = subprocess.Popen(
            args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        assert self._proc.stdout is not None
        line = self._proc.stdout.readline()
        if "listening" not in line:
            self.stop()
            raise RuntimeError(f"linkemu did not start: {line}")
        deadline = time.monotonic() + 5
        while not port_open(*listen) and time.monotonic() < deadline:
            time.sleep(0.01)

    def stop(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            self._proc.terminate()
        try:
            self._proc.wait(5)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait(5)
        if self._proc.stdout is not None:
            self._proc.stdout.close()
