"""TLS to the broker against a mosquitto started with a test CA: verification, hostname check, client
certificates, and a clear error when the server's certificate is not trusted."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import pytest

from gateway.local_broker import LocalBroker, free_port
from tests.certs import TestCA
from tests.support import GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker


def _tls_broker(tmp: Path, ca: TestCA, server_dns: tuple[str, ...], *, require_client_cert: bool = False,
                users: dict[str, str] | None = None) -> LocalBroker:  # fmt: skip
    server = ca.issue("broker", dns=server_dns)
    port = free_port()
    lines = "\n".join(
        [
            f"listener {port} 127.0.0.1",
            f"cafile {ca.pair.cert}",
            f"certfile {server.cert}",
            f"keyfile {server.key}",
            f"require_certificate {'true' if require_client_cert else 'false'}",
        ]
    )
    return LocalBroker(port, listener_lines=lines, users=users, workdir=tmp / f"mosq-{port}").start()


def _settings(url: str, **broker: object) -> object:
    s = gateway_settings(1, [], broker={"url": url, **broker})
    return s


@pytest.fixture
def ca(tmp_path: Path) -> TestCA:
    return TestCA(tmp_path)


def test_verified_tls_with_username_and_password(tmp_path: Path, ca: TestCA) -> None:
    broker = _tls_broker(tmp_path, ca, ("localhost",), users={"gw": "tls-pass-123"})
    try:
        settings = _settings(f"mqtts://localhost:{broker.port}", ca_file=str(ca.pair.cert), username="gw",
                             password="tls-pass-123")  # fmt: skip
        with GatewayThread(settings) as gw:
            assert gw.app.bridge.subscribed
    finally:
        broker.stop()


def test_untrusted_server_certificate_is_refused_with_a_clear_error(
    tmp_path: Path, ca: TestCA, caplog: pytest.LogCaptureFixture
) -> None:
    (tmp_path / "other").mkdir()
    other = TestCA(tmp_path / "other", name="someone else")
    broker = _tls_broker(tmp_path, ca, ("localhost",))
    try:
        settings = _settings(f"mqtts://localhost:{broker.port}", ca_file=str(other.pair.cert))
        with caplog.at_level(logging.ERROR, logger="gateway.mqtt"):
            gw = GatewayThread(settings).start(connected=False)
            try:
                wait_until(lambda: gw.app.bridge.last_error, 10, what="a diagnosis")
                assert not gw.app.bridge.connected
            finally:
                gw.stop()
        assert "certificate was refused" in gw.app.bridge.last_error
        assert "certificate was refused" in caplog.text and "certificate" in gw.app.bridge.last_error
    finally:
        broker.stop()


def test_hostname_check(tmp_path: Path, ca: TestCA) -> None:
    broker = _tls_broker(tmp_path, ca, ("broker.example",))  # the certificate names another host
    try:
        strict = _settings(f"mqtts://localhost:{broker.port}", ca_file=str(ca.pair.cert))
        gw = GatewayThread(strict).start(connected=False)
        try:
            wait_until(lambda: gw.app.bridge.last_error, 10, what="a diagnosis")
            assert (
                "Hostname mismatch" in gw.app.bridge.last_error
                or "hostname" in gw.app.bridge.last_error.lower()
            )
        finally:
            gw.stop()
        relaxed = _settings(
            f"mqtts://localhost:{broker.port}", ca_file=str(ca.pair.cert), tls_hostname_check=False
        )
        with GatewayThread(relaxed) as gw:
            assert gw.app.bridge.subscribed
    finally:
        broker.stop()


def test_client_certificate(tmp_path: Path, ca: TestCA) -> None:
    broker = _tls_broker(tmp_path, ca, ("localhost",), require_client_cert=True)
    client = ca.issue("gateway-client", client=True)
    try:
        without = _settings(f"mqtts://localhost:{broker.port}", ca_file=str(ca.pair.cert))
        gw = GatewayThread(without).start(connected=False)
        try:
            time.sleep(1.0)
            assert not gw.app.bridge.connected
        finally:
            gw.stop()
        with_cert = _settings(f"mqtts://localhost:{broker.port}", ca_file=str(ca.pair.cert),
                              cert_file=str(client.cert), key_file=str(client.key))  # fmt: skip
        with GatewayThread(with_cert) as gw:
            assert gw.app.bridge.subscribed
    finally:
        broker.stop()
