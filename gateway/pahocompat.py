"""The one place that touches a private member of paho-mqtt, because paho's public API has no way to do it.

paho 2.x keeps a wake-up socket pair per ``loop_start()`` and a network socket that outlive
``loop_stop()``; it frees them only when the client object is collected (``Client.__del__``), which a
reference cycle can delay until an unclosed-socket warning fires later, and a new ``loop_start()`` opens
a new pair without closing the old one. Two wrappers reach the private methods that free them:

- :func:`release_sockets` → ``Client._reset_sockets(sockpair_only=...)`` (what ``__del__`` calls);
- :func:`close_network_socket` → ``Client._sock_close()`` (what ``reconnect()`` calls first).

Nothing else in the package reads or writes a private attribute of paho (``tests/test_library_internals.py``
greps for it). The internals were read in paho-mqtt 2.0-2.2; ``pyproject.toml`` pins ``paho-mqtt<2.3``, and
:data:`CHECKED` plus ``tests/test_library_internals.py`` fail as soon as an installed paho lacks them or
changed their signature, so a new paho is checked before it is allowed. Where a private member is
missing at run time the wrappers do nothing (the sockets are then closed when the client is collected).
Knows nothing of brokers, topics or the gateway.
"""

from __future__ import annotations

import contextlib
import inspect
from typing import Any

import paho.mqtt.client as paho

#: paho-mqtt releases whose internals these wrappers were read against (``pyproject.toml`` pins below the
#: next minor release)
CHECKED = ("2.0", "2.1", "2.2")

#: the private members used, with the parameters each must take
PRIVATE_MEMBERS: dict[str, tuple[str, ...]] = {
    "_reset_sockets": ("self", "sockpair_only"),
    "_sock_close": ("self",),
}


def private_members_present() -> list[str]:
    """What is wrong with the installed paho for these wrappers (empty: nothing): a member gone or with
    other parameters."""
    problems: list[str] = []
    for name, params in PRIVATE_MEMBERS.items():
        member = getattr(paho.Client, name, None)
        if not callable(member):
            problems.append(f"paho.Client.{name} is gone")
            continue
        found = tuple(inspect.signature(member).parameters)
        if found != params:
            problems.append(f"paho.Client.{name}{found} is not {params}")
    return problems


def release_sockets(client: paho.Client, *, sockpair_only: bool = False) -> None:
    """Close what paho keeps open after ``loop_stop()``: the wake-up socket pair that ``loop_start()``
    made and, unless ``sockpair_only``, the network socket. Harmless when already closed."""
    reset: Any = getattr(client, "_reset_sockets", None)  # private: see the module docstring
    if reset is not None:
        with contextlib.suppress(Exception):
            reset(sockpair_only=sockpair_only)


def close_network_socket(client: paho.Client) -> None:
    """Close the network socket of a connection attempt that failed (TLS refused, no CONNACK) without
    touching the client's state otherwise. Harmless when there is none."""
    close: Any = getattr(client, "_sock_close", None)  # private: see the module docstring
    if close is not None:
        with contextlib.suppress(Exception):
            close()
