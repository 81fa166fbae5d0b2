"""Missing hardware (issue #22 item 8): a link that cannot open is said once with a hint, then quietly
retried with a backoff; its return is one line. The state machine on a clock, then a real gateway with a
serial port that is not there."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from adapters.absence import BACKOFF_AFTER, MAX_RETRY, Absence, concise, hint_for
from gateway.local_broker import LocalBroker
from tests.support import GatewayThread, gateway_settings, wait_until

PYSERIAL = (
    "cannot open /dev/serial/by-id/usb-X: [Errno 2] could not open port /dev/serial/by-id/usb-X: "
    "[Errno 2] No such file or directory: '/dev/serial/by-id/usb-X'"
)


def test_errors_are_made_concise_and_get_the_likeliest_hint() -> None:
    assert concise(PYSERIAL) == "cannot open /dev/serial/by-id/usb-X: No such file or directory"
    assert "ls -l /dev/serial/by-id" in hint_for(concise(PYSERIAL))
    assert "dialout" in hint_for("cannot open /dev/ttyUSB0: Permission denied")
    assert "ip link set can0 up type can bitrate 1000000" in hint_for(
        "cannot open socketcan can0: Network is down"
    )
    assert "network_mode: host" in hint_for(
        "cannot open socketcan can0: Address family not supported by protocol"
    )


def test_an_absent_link_is_said_once_then_backs_off_and_reminds_rarely() -> None:
    a = Absence(reopen_interval=2.0)
    now, levels, delays = 0.0, [], []
    first = a.failed(now, PYSERIAL, "aircraft M600-1")
    assert first.level == logging.WARNING and "(hint: is it plugged in?" in first.message
    assert first.message.count("/dev/serial/by-id/usb-X") == 1
    while now < 3600:
        d = a.failed(now, PYSERIAL, "aircraft M600-1")
        levels.append((now, d.level))
        delays.append(d.delay)
        now += d.delay
    assert delays[0] == 2.0 and max(delays) == MAX_RETRY
    assert all(d == 2.0 for t, d in zip([t for t, _ in levels], delays, strict=True) if t < BACKOFF_AFTER)
    infos = [t for t, lvl in levels if lvl == logging.INFO]
    assert not [lvl for _, lvl in levels if lvl == logging.WARNING]  # the same error is not said again
    assert 4 <= len(infos) <= 8 and infos[0] >= 60  # reminders at 1, 2, 4, 8 … minutes
    # another error is news; the link opening is one line and resets the backoff
    assert a.failed(now, "cannot open /dev/x: Permission denied", "aircraft M600-1").level == logging.WARNING
    back = a.opened(now + 1, "aircraft M600-1")
    assert back is not None and back.startswith("aircraft M600-1: link open after 36")
    assert a.opened(now + 2, "aircraft M600-1") is None
    assert a.failed(now + 3, PYSERIAL, "aircraft M600-1").delay == 2.0


@pytest.mark.broker
def test_a_gateway_without_its_serial_device_logs_it_once(
    broker: LocalBroker, caplog: pytest.LogCaptureFixture, tmp_path: Path
) -> None:
    caplog.set_level(logging.DEBUG, logger="adapters")
    missing = f"{tmp_path}/ttyUSB-missing"
    device = {"type": "osdk", "sn": "OSDK-ABSENT-1", "url": missing, "reopen_interval": 0.1}
    with GatewayThread(
        gateway_settings(broker.port, [device]),
    ) as gw:
        wait_until(lambda: gw.app.devices.by_sn("OSDK-ABSENT-1")._absence.attempts >= 10, 10, what="retries")
    lines = [r for r in caplog.records if "OSDK-ABSENT-1" in r.getMessage()]
    loud = [r for r in lines if r.levelno >= logging.INFO]
    assert len(loud) == 1 and loud[0].levelno == logging.WARNING, [r.getMessage() for r in loud]
    assert loud[0].getMessage().count(missing) == 1 and "hint:" in loud[0].getMessage()
    assert len(lines) >= 10  # the repeats are there at DEBUG
