"""The device-family registry: the one place that says which families exist and where their parts live.

A family is a name (the ``type`` of a ``[[devices]]`` entry) and a :class:`Family` record naming, by
import path, its settings model, its adapter, its ``describe`` module (``dji-gateway decode``/``encode``
and the console's frame inspector), its simulator module and its extension methods. Nothing is imported
until it is asked for (python-can's ``can.interfaces.BACKENDS`` is the model): listing the families
costs nothing, and a family whose optional dependency is missing only fails when it is used.

Where families come from, in this order:

1. the three built into this distribution (:data:`BUILTIN`);
2. the ``dji_gateway.families`` entry points of installed distributions (each names a :class:`Family`
   or a zero-argument callable returning one), read once on first use;
3. :func:`register`, called by a program or a test before it builds the gateway's settings.

Every gateway site iterates this registry (the settings union, the composition root, the CLIs with
``--simulate``, ``decode``/``encode``, the schema export, the console's frame inspector); no module under
``gateway/`` imports a family package. Must not know the gateway, MQTT or any wire protocol.

Adding a family (docs/architecture.md, "Adding a device family"): write the package, describe it in a
:class:`Family`, register it here (built in) or by entry point / :func:`register` (outside).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING, Any, Protocol

from adapters.clock import SYSTEM_CLOCK, Clock

if TYPE_CHECKING:
    from pydantic import BaseModel

    from adapters.base import Adapter

__all__ = [
    "BUILTIN",
    "ENTRY_POINT_GROUP",
    "CliOption",
    "Extension",
    "Family",
    "InProcessSim",
    "UnknownFamily",
    "all_families",
    "get",
    "names",
    "register",
    "settings_models",
    "unregister",
]

#: The entry-point group an installed distribution declares its families in.
ENTRY_POINT_GROUP = "dji_gateway.families"

#: One extension method: (method, request or event model, reply model, one-line summary).
Extension = tuple[str, type[Any], type[Any], str]


class UnknownFamily(LookupError):
    """No family of that name is registered."""


class InProcessSim(Protocol):
    """A simulator started inside the gateway's process (``dji-gateway run --simulate``)."""

    def stop(self) -> None: ...


def _load(ref: str | Any) -> Any:
    """``"package.module:attribute"`` imported now; a ``"package.module"`` is the module; anything else
    (an object given directly, as a test registering a family does) is returned as it is."""
    if not isinstance(ref, str):
        return ref
    module, _, attribute = ref.partition(":")
    loaded = importlib.import_module(module)
    return getattr(loaded, attribute) if attribute else loaded


@dataclass(frozen=True, slots=True)
class CliOption:
    """An option of ``dji-gateway decode``/``encode`` that one family's describe module reads (declared
    here, so building the command line imports no family)."""

    flag: str  # "--season"
    option: str  # the describe option it sets ("season")
    help: str
    choices: tuple[str, ...] | None = None
    integer: bool = False  # parsed with int(text, 0): 0x… accepted
    commands: tuple[str, ...] = ("decode", "encode")  # which of the two take it


@dataclass(frozen=True, slots=True)
class Family:
    """One device family. Every reference is an import path (``"pkg.module:Name"``, or ``"pkg.module"``
    for a module) resolved on first use, or the object itself.

    - ``settings``: the pydantic model of one ``[[devices]]`` entry (frozen, ``extra="forbid"``: see
      ``adapters.config.DEVICE_MODEL_CONFIG``); its ``type`` field is ``Literal[name]``, and it has ``sn``,
      ``product`` (the device's Cloud API domain and type: ``adapters.config.ProductSettings``) and
      ``osd_period`` (None: the gateway's); optionally ``payload_index`` (unique per gateway) and ``url``
      (a serial path the gateway checks before it starts).
    - ``adapter``: called with the validated settings and the gateway's clock (``factory(settings,
      clock=clock)``, an :class:`adapters.clock.Clock`: every timer the adapter keeps runs on it), returns
      an :class:`adapters.base.Adapter`.
    - ``describe``: the CLI codec module: ``COMMANDS``, ``decode_bytes(data, **options)``,
      ``encode_command(name, seq, fields, **options)``; optionally ``decode_can_lines``/``encode_can``
      (a CAN family), ``CLI_OPTIONS`` (argparse options it reads), ``options_for(settings)`` (the decode
      options that match a configured device), ``frame_rules(options)`` (how the frame inspector cuts
      its link's bytes into frames) and ``REPLY_OPTION``/``REPLY_FLAG`` (how a reply names its command).
    - ``simulator``: a module with ``main(argv) -> int`` (``dji-gateway simulate <name>``) and
      optionally ``in_process(device_settings) -> (InProcessSim, device_settings) | None`` (what
      ``--simulate`` starts for a device entry, with the entry pointed at it).
    - ``extensions``: a module with ``EXTENSIONS`` (services) and optionally ``EVENT_EXTENSIONS``.
    - ``tour``: the ``[[devices]]`` entry ``dji-gateway run --simulate`` adds (None: not in the tour).
    - ``cli_options``: the ``decode``/``encode`` options its describe module reads.
    """

    name: str
    settings: str | type[BaseModel]
    adapter: str | Callable[..., Adapter]
    describe: str | ModuleType | None = None
    simulator: str | ModuleType | None = None
    extensions: str | ModuleType | None = None
    tour: Mapping[str, Any] | None = field(default=None)
    cli_options: tuple[CliOption, ...] = ()

    def settings_model(self) -> type[BaseModel]:
        """The settings model; a model whose ``type`` does not default to the family's name is refused
        (the settings' union tells families apart by it)."""
        model: type[BaseModel] = _load(self.settings)
        kind = model.model_fields.get("type")
        if kind is None or kind.default != self.name:
            raise TypeError(f"family {self.name!r}: {model.__name__}.type must be Literal[{self.name!r}]")
        return model

    def build(self, settings: Any, clock: Clock = SYSTEM_CLOCK) -> Adapter:
        """The adapter for one validated ``[[devices]]`` entry of this family, keeping time on ``clock``."""
        factory: Callable[..., Adapter] = _load(self.adapter)
        return factory(settings, clock=clock)

    def describe_module(self) -> ModuleType | None:
        return None if self.describe is None else _load(self.describe)

    def simulator_module(self) -> ModuleType | None:
        return None if self.simulator is None else _load(self.simulator)

    def service_extensions(self) -> Sequence[Extension]:
        return self._extensions("EXTENSIONS")

    def event_extensions(self) -> Sequence[Extension]:
        return self._extensions("EVENT_EXTENSIONS")

    def _extensions(self, name: str) -> Sequence[Extension]:
        if self.extensions is None:
            return ()
        found: Sequence[Extension] = getattr(_load(self.extensions), name, ())
        return found


#: The families of this distribution. Order matters where the gateway lists them (the settings union's
#: error messages, ``decode``/``encode``/``simulate`` choices, the ``--simulate`` tour's devices).
BUILTIN: tuple[Family, ...] = (
    Family(
        name="rsdk",
        settings="adapters.rsdk.config:RsdkDeviceSettings",
        adapter="adapters.rsdk.adapter:GimbalAdapter",
        describe="adapters.rsdk.describe",
        simulator="adapters.rsdk.sim",
        extensions="adapters.rsdk.extensions",
        cli_options=(
            CliOption(
                "--angle-order",
                "angle_order",
                "rsdk: angle order of legacy-firmware 0x0E 0x02 replies (default the seed's yaw_roll_pitch)",
                choices=("yaw_roll_pitch", "yaw_pitch_roll"),
                commands=("decode",),
            ),
        ),
        # a gimbal on a virtual CAN bus of its own, with its in-process simulator
        tour={
            "type": "rsdk",
            "sn": "RSDK-SIM-0001",
            "payload_index": "20-0-0",
            "interface": "virtual",
            "channel": "djigw-sim-RSDK-SIM-0001",
            "drc_drive": True,  # live-control sticks turn it (with payload authority): docs/drc.md
        },
    ),
    Family(
        name="osdk",
        settings="adapters.osdk.config:OsdkDeviceSettings",
        adapter="adapters.osdk.adapter:AircraftAdapter",
        describe="adapters.osdk.describe",
        simulator="adapters.osdk.sim",
        extensions="adapters.osdk.extensions",
        tour={"type": "osdk", "sn": "OSDK-SIM-0001", "url": "sim://osdk"},
        cli_options=(
            CliOption(
                "--firmware", "firmware", "osdk: flight controller generation", choices=("new", "m100")
            ),
        ),
    ),
    Family(
        name="robomaster",
        settings="adapters.robomaster.config:RobomasterDeviceSettings",
        adapter="adapters.robomaster.adapter:RobotAdapter",
        describe="adapters.robomaster.describe",
        simulator="adapters.robomaster.sim",
        extensions="adapters.robomaster.extensions",
        # the robot's gimbal answers camera_screen_drag and gimbal_reset on this payload index
        tour={
            "type": "robomaster",
            "sn": "RM-SIM-0001",
            "payload_index": "39-0-7",
            "url": "sim://robomaster",
        },
        cli_options=(
            CliOption(
                "--season", "season", "robomaster: referee protocol season", choices=("2024", "2025", "2026")
            ),
            CliOption(
                "--control-cmd-id", "control_cmd_id", "robomaster: team-defined control cmd_id", integer=True
            ),
        ),
    ),
)

_lock = threading.Lock()
_registered: dict[str, Family] = {f.name: f for f in BUILTIN}
_entry_points_read = False


def _read_entry_points() -> None:
    global _entry_points_read
    with _lock:
        if _entry_points_read:
            return
        _entry_points_read = True
        points = list(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))
    for point in points:
        loaded = point.load()
        family = loaded if isinstance(loaded, Family) else loaded()
        if not isinstance(family, Family):
            raise TypeError(f"entry point {point.name!r} in {ENTRY_POINT_GROUP} is not a Family")
        if family.name not in _registered:  # a family of this distribution wins over a plug-in
            register(family)


def register(family: Family, *, replace: bool = False) -> Family:
    """Add ``family`` (before the gateway's settings are read). A name taken by another family is refused
    unless ``replace``."""
    if not family.name.isidentifier():
        raise ValueError(f"family name {family.name!r} must be an identifier")
    with _lock:
        if family.name in _registered and not replace and _registered[family.name] is not family:
            raise ValueError(f"a device family named {family.name!r} is already registered")
        _registered[family.name] = family
    return family


def unregister(name: str) -> None:
    """Remove a family added by :func:`register` (tests); a built-in family cannot be removed."""
    if any(f.name == name for f in BUILTIN):
        raise ValueError(f"{name!r} is built in")
    with _lock:
        _registered.pop(name, None)


def all_families() -> Iterator[Family]:
    """Every registered family, the built-in ones first, in registration order."""
    _read_entry_points()
    with _lock:
        families = list(_registered.values())
    yield from families


def names() -> tuple[str, ...]:
    return tuple(f.name for f in all_families())


def get(name: str) -> Family:
    with _lock:
        family = _registered.get(name)
    if family is None:  # maybe a plug-in's: read the entry points (once) and look again
        _read_entry_points()
        with _lock:
            family = _registered.get(name)
    if family is None:
        raise UnknownFamily(f"no device family {name!r} (known: {', '.join(names())})")
    return family


def settings_models() -> tuple[type[BaseModel], ...]:
    """Every family's settings model (imports each family's settings module)."""
    return tuple(f.settings_model() for f in all_families())
