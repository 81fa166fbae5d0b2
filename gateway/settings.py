"""Gateway settings: one pydantic-settings class, read once at start-up and passed down.

Sources, strongest first: ``DJIGW_``-prefixed environment variables (nested with ``__``, e.g.
``DJIGW_BROKER__PASSWORD``), then the TOML file given with ``--config``. Secrets have no defaults
and are ``SecretStr`` so they never reach a log line or an error message. No import-time singleton.

Why this module is longer than 500 lines: it is the one settings class and its sections (broker,
dispatcher, live control, cloud control, metrics, console, devices), each field with its range and the
description the README's configuration reference is generated from; split, the reference and the
cross-section checks would have to gather them again.
"""

from __future__ import annotations

import ipaddress
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Union
from urllib.parse import urlsplit

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    SecretStr,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from adapters import families
from adapters.config import ProductSettings
from schemas.status import MAX_SUB_DEVICES

__all__ = [
    "BrokerEndpoint",
    "BrokerSettings",
    "CloudControlSettings",
    "ConfigError",
    "ConsoleSettings",
    "DeviceSettings",
    "DispatcherSettings",
    "DrcSettings",
    "GatewaySettings",
    "MetricsSettings",
    "ProductSettings",
    "VideoSettings",
    "VideoSource",
    "load_settings",
]

_STRICT = ConfigDict(extra="forbid", frozen=True)


class ConfigError(ValueError):
    """A configuration that cannot run; the message is one line naming the field."""


_DEFAULT_PORTS = {"mqtt": 1883, "tcp": 1883, "mqtts": 8883, "ssl": 8883, "ws": 80, "wss": 443}


@dataclass(frozen=True, slots=True)
class BrokerEndpoint:
    """One broker node, from one ``broker.url`` entry."""

    url: str
    host: str
    port: int
    transport: Literal["tcp", "websockets"]
    tls: bool
    ws_path: str

    @classmethod
    def parse(cls, url: str) -> BrokerEndpoint:
        parts = urlsplit(url)
        if parts.scheme not in _DEFAULT_PORTS:
            raise ValueError(f"{url!r}: scheme must be mqtt://, mqtts://, ws:// or wss://")
        if not parts.hostname:
            raise ValueError(f"{url!r}: missing host")
        try:
            port = parts.port or _DEFAULT_PORTS[parts.scheme]
        except ValueError:
            raise ValueError(f"{url!r}: bad port") from None
        return cls(
            url=url,
            host=parts.hostname,
            port=port,
            transport="websockets" if parts.scheme in {"ws", "wss"} else "tcp",
            tls=parts.scheme in {"mqtts", "wss", "ssl"},
            ws_path=parts.path or "/mqtt",
        )

    def where(self) -> str:
        return f"{self.host}:{self.port}"


class BrokerSettings(BaseModel):
    model_config = _STRICT
    url: str | list[str] = Field(
        "mqtt://127.0.0.1:1883",
        description="mqtt://, mqtts://, ws:// or wss:// host:port[/path]; or a list of them (the nodes of "
        "one cluster): the gateway uses the first that answers and moves to the next on loss",
    )
    username: str | None = None
    password: SecretStr | None = None
    client_id: str | None = Field(None, description="default: djigw-<gateway_sn>")
    protocol: Literal["5", "3.1.1"] = "5"
    keepalive: int = Field(30, ge=5, le=3600)
    ca_file: Path | None = None
    cert_file: Path | None = None
    key_file: Path | None = None
    tls_hostname_check: bool = True
    session_expiry: int = Field(
        600, ge=0, description="MQTT 5 session expiry (s): QoS 1 requests survive a reconnect"
    )
    reconnect_min: float = Field(0.5, gt=0, le=60)
    reconnect_max: float = Field(30.0, gt=0, le=600)
    probe_interval: float = Field(
        0.5,
        ge=0.05,
        le=60,
        description="while no broker answers, a TCP probe of every url this often (jittered to ½–1×): "
        "the gateway is back about this long after the broker or the network is",
    )
    connect_timeout: float = Field(5.0, gt=0, le=60, description="TCP + TLS + CONNACK of one attempt (s)")
    stall_timeout: float = Field(
        2.0,
        gt=0,
        le=60,
        description="a connection whose data TCP keeps retransmitting this long (s) is given up and remade "
        "(live control riding it ends); at most ⅔ of drc.heartbeat_timeout is used",
    )
    liveness_interval: float = Field(
        5.0,
        ge=0,
        le=3600,
        description="prove the link receives: after every SUBACK and then this often (s, jittered ½–1×) "
        "a probe is published to a topic the link subscribes to (djigw/<client id>/probe); 0: off "
        "(a broker whose ACL silently drops the probe needs it allowed, or this off)",
    )
    liveness_timeout: float = Field(
        3.0,
        gt=0,
        le=60,
        description="a probe not back within this (s) marks the link deaf: resubscribe, then reconnect "
        "(next url)",
    )
    takeover_backoff_max: float = Field(
        120.0,
        ge=30,
        le=3600,
        description="another client took our client id: reconnect after 2 s, doubling up to this (s)",
    )
    telemetry_buffer: int = Field(
        1000, ge=0, description="osd messages kept while the broker is unreachable; the oldest go first"
    )
    telemetry_buffer_age: float = Field(
        300.0, gt=0, description="buffered osd older than this (s) is dropped, not delivered"
    )
    inbound_queue: int = Field(
        1000, ge=10, description="received messages held for the loop; more are dropped"
    )
    max_payload: int = Field(65536, ge=1024, description="inbound payloads larger than this are refused")

    @field_validator("url")
    @classmethod
    def _url(cls, v: str | list[str]) -> str | list[str]:
        urls = [v] if isinstance(v, str) else list(v)
        if not urls:
            raise ValueError("give at least one broker url")
        endpoints = [BrokerEndpoint.parse(u) for u in urls]
        if len({(e.transport, e.tls) for e in endpoints}) > 1:
            raise ValueError("every broker url must use the same scheme (all mqtt://, all mqtts:// …)")
        if len({(e.host, e.port) for e in endpoints}) != len(endpoints):
            raise ValueError("a broker url is listed twice")
        return v

    def for_live_control(self, heartbeat_timeout: float) -> BrokerSettings:
        """These settings with ``stall_timeout`` at most ⅔ of the DRC heartbeat timeout: a partition
        longer than the heartbeat timeout then always drops the connection, so live control riding it
        ends instead of resuming when the link comes back."""
        limit = round(heartbeat_timeout * 2 / 3, 3)
        return self if self.stall_timeout <= limit else self.model_copy(update={"stall_timeout": limit})

    @property
    def urls(self) -> tuple[str, ...]:
        return (self.url,) if isinstance(self.url, str) else tuple(self.url)

    @property
    def endpoints(self) -> tuple[BrokerEndpoint, ...]:
        return tuple(BrokerEndpoint.parse(u) for u in self.urls)

    # the first node's view, for the callers that take one broker (the console, DRC's dedicated links)
    @property
    def transport(self) -> Literal["tcp", "websockets"]:
        return self.endpoints[0].transport

    @property
    def tls(self) -> bool:
        return self.endpoints[0].tls

    @property
    def host(self) -> str:
        return self.endpoints[0].host

    @property
    def port(self) -> int:
        return self.endpoints[0].port

    @property
    def ws_path(self) -> str:
        return self.endpoints[0].ws_path

    def is_node(self, host: str, port: int, tls: bool) -> bool:
        """Whether ``host:port`` is one of the configured nodes (DRC on "the main broker")."""
        return any((e.host, e.port, e.tls) == (host, port, tls) for e in self.endpoints)


class DispatcherSettings(BaseModel):
    model_config = _STRICT
    request_timeout: float = Field(
        1.0, gt=0, le=2.5, description="device deadline; the reply is always < 3 s"
    )
    # longer than a broker's redelivery of an unacknowledged QoS 1 request (NATS: mqtt.ack_wait, 30 s by
    # default, again every 30 s): a copy redelivered after a failover is answered from the cache, not run
    # again (at 30 s the copy arriving 30.008 s later took a second photo: tests/test_dispatcher_limits.py)
    reply_cache_seconds: float = Field(120.0, ge=0)
    require_authority: bool = Field(
        True,
        description=(
            "camera/gimbal/flight methods need a prior *_authority_grab "
            "(wayline tasks and return home do not: docs/cloud-api.md)"
        ),
    )
    event_retries: int = Field(3, ge=0, le=10)
    event_retry_interval: float = Field(3.0, gt=0)
    max_pending: int = Field(256, ge=1, description="requests in flight at once; more get 314000 busy")


class DrcSettings(BaseModel):
    """Live flight control (DRC): the failsafe timings and the stick conventions."""

    model_config = _STRICT
    stick_timeout: float = Field(0.5, gt=0, le=5, description="no drone_control this long → zero set-point")
    heartbeat_timeout: float = Field(3.0, gt=0, le=30, description="no heart_beat this long → stop, 514301")
    idle_timeout: float = Field(60.0, gt=0, le=3600, description="no heart_beat this long → leave DRC")
    stream_hz: float = Field(25.0, ge=20, le=50, description="set-point stream to the devices")
    max_stick_rate: float = Field(
        100.0,
        ge=20,
        le=1000,
        description="drone_control read per second at most (repeats count); more is dropped unread",
    )
    enter_timeout: float = Field(2.0, gt=0, le=2.5, description="wait for the DRC broker (s)")
    x_sign: Literal[1, -1] = Field(1, description="seed: +x is left; -1 when your cloud sends +x right")
    y_sign: Literal[1, -1] = Field(1, description="seed: +y is forward; -1 when your cloud sends +y back")
    swap_xy: bool = Field(False, description="true when your cloud sends x forward and y sideways")
    stick_horizontal: float = Field(
        10.0, gt=0, le=17, description="stick_control: m/s forward/right at full roll or pitch (1024 ± 660)"
    )
    stick_up: float = Field(5.0, gt=0, le=5, description="stick_control: m/s up at full throttle")
    stick_down: float = Field(4.0, gt=0, le=4, description="stick_control: m/s down at zero throttle")
    stick_yaw_rate: float = Field(90.0, gt=0, le=90, description="stick_control: °/s clockwise at full yaw")
    drone_state_hz: float = Field(
        1.0, ge=0, le=10, description="drc_drone_state_push a second during DRC (0: not sent)"
    )
    batteries_hz: float = Field(
        1.0, ge=0, le=10, description="drc_batteries_info_push a second during DRC (0: not sent)"
    )


class CloudControlSettings(BaseModel):
    """Cloud-control authorisation (``cloud_control_auth_request``, RC Plus 2 / RC Pro): who is granted
    at once, how long the operator has to answer the others, and whether live control needs it."""

    model_config = _STRICT
    allow: tuple[str, ...] = Field(
        (), max_length=256, description="user_id values granted at once (nobody else holding control)"
    )
    timeout: float = Field(
        60.0, gt=0, le=3600, description="the operator's time to accept (console, CLI); then denied"
    )
    required: bool = Field(
        False,
        description="drc_mode_enter needs a granted cloud_control_auth_request even before any cloud "
        "has sent one (once one has, it always does)",
    )

    @field_validator("allow")
    @classmethod
    def _user_ids(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        if any(not 1 <= len(user) <= 128 for user in value):
            raise ValueError("each user_id is 1..128 characters")
        return value


class WaylineSettings(BaseModel):
    """Wayline tasks (flighttask_*)."""

    model_config = _STRICT
    #: refuse (flighttask_prepare 314003) a route with WPML actions the aircraft cannot carry out; off: they
    #: are skipped and listed (the prepare reply's and the progress' x_skipped_actions)
    strict_actions: bool = Field(False, description="refuse routes with actions the aircraft would skip")


#: A video source: a network URL ffmpeg opens, a V4L2 device, or a test pattern (``test:``).
_SOURCE_SCHEMES = ("rtsp", "rtsps", "rtmp", "rtmps", "srt", "udp", "tcp", "http", "https")


def _check_source(value: str) -> str:
    if value == "test:" or value.startswith("test:"):
        if value not in ("test:", "test:testsrc2", "test:smptebars"):
            raise ValueError("a test source is test:, test:testsrc2 or test:smptebars")
        return value
    if value.startswith("/dev/video"):
        return value
    scheme = urlsplit(value).scheme.lower()
    if scheme not in _SOURCE_SCHEMES:
        raise ValueError(f"a source is a {', '.join(_SOURCE_SCHEMES)} URL, /dev/videoN or test:")
    return value


class VideoSource(BaseModel):
    """One camera picture of a device, as the gateway's computer receives it (docs/video.md)."""

    model_config = _STRICT
    sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$",
                    description="the device (a [[devices]] sn) whose camera this is")  # fmt: skip
    camera_index: str = Field(
        "0-0-0", pattern=r"^[0-9]{1,5}-[0-9]{1,5}-[0-9]{1,5}$",
        description="{type-subtype-gimbalindex} in video_id (the payload_index of the camera's gimbal)",
    )  # fmt: skip
    video_index: str = Field("normal-0", pattern=r"^[A-Za-z0-9_]{1,16}(-[0-9]{1,3})?$",
                             description="the stream's index in video_id")  # fmt: skip
    source: str = Field(description="rtsp://, rtmp://, srt://, udp://, tcp://, http(s):// URL, /dev/videoN "
                        "(V4L2) or test: (a moving pattern)")  # fmt: skip
    codec: Literal["h264", "other"] = Field(
        "other", description="the source's codec: h264 is passed through (no re-encode) at quality 0 to RTMP"
    )
    lenses: dict[Literal["wide", "zoom", "ir"], str] = Field(
        default_factory=dict, description="other lenses: video_type -> source (live_lens_change)"
    )

    @field_validator("source")
    @classmethod
    def _source(cls, value: str) -> str:
        return _check_source(value)

    @field_validator("lenses")
    @classmethod
    def _lens_sources(cls, value: dict[str, str]) -> dict[str, str]:
        for source in value.values():
            _check_source(source)
        return value

    @property
    def video_id(self) -> str:
        return f"{self.sn}/{self.camera_index}/{self.video_index}"


class VideoSettings(BaseModel):
    """Live video (``live_*``): the sources and the supervised ffmpeg pipelines (docs/video.md)."""

    model_config = _STRICT
    sources: list[VideoSource] = Field(
        default_factory=list,
        max_length=64,
        description="[[video.sources]]: sn, camera_index, video_index, source, codec, lenses (docs/video.md)",
    )
    test_pattern: bool = Field(
        False, description="every device also has a test-pattern video (run --simulate sets it)"
    )
    ffmpeg: str = Field("ffmpeg", description="the ffmpeg executable (apt-get install ffmpeg)")
    max_streams: int = Field(2, ge=1, le=16, description="streams at once (coexist_video_number_max)")
    start_wait: float = Field(
        2.0, gt=0, le=2.5, description="how long live_start_push waits for the first frames before answering"
    )
    stall_timeout: float = Field(5.0, gt=0, description="restart a pipeline without a frame this long")
    start_timeout: float = Field(
        20.0,
        gt=0,
        description="restart a pipeline with no first frame this long after it started (at least "
        "stall_timeout; WHIP's publisher starts Python and aiortc, POSTs its offer and connects ICE and DTLS "
        "first)",
    )
    backoff_initial: float = Field(0.5, gt=0, description="first restart delay after a failure (doubles)")
    backoff_max: float = Field(10.0, gt=0, description="longest restart delay")
    threads: int = Field(2, ge=1, le=16, description="encoder threads per pipeline (CPU bound)")
    memory_mb: int = Field(1024, ge=128, description="address-space limit per pipeline (prlimit --as)")
    nice: int = Field(10, ge=0, le=19, description="pipelines run at this nice level")
    preview: bool = Field(True, description="pipelines also feed the web console's preview (fragmented MP4)")
    ice_servers: list[str] = Field(
        default_factory=list,
        max_length=8,
        description="WHIP (url_type 4): STUN/TURN servers for ICE, e.g. stun:stun.example.com:3478 (none: "
        "host candidates only, enough for a WHIP endpoint on a public address)",
    )


class MetricsSettings(BaseModel):
    """The HTTP endpoint for Prometheus (``/metrics``), health checks (``/healthz``) and ``dji-gateway
    status`` (``/status``)."""

    model_config = _STRICT
    enabled: bool = Field(True, description="serve /metrics, /healthz and /status")
    host: str = Field(
        "127.0.0.1", description="listen address; 0.0.0.0 in a container that Prometheus scrapes"
    )
    port: int = Field(9108, ge=0, le=65535, description="HTTP port (0: any free port, logged at start)")


#: A console token shorter than this is refused: it guards commands that move aircraft.
MIN_TOKEN_LENGTH = 16


def is_loopback(host: str) -> bool:
    """True for addresses only this machine reaches: 127.0.0.0/8, ::1 and ``localhost``."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class ConsoleSettings(BaseModel):
    """The web console at ``/`` of the metrics endpoint (docs/console.md): who may act, what it shows."""

    model_config = _STRICT
    enabled: bool = Field(True, description="serve the web console at / (beside /metrics, /healthz, /status)")
    token: SecretStr | None = Field(
        None,
        description="actions need it (header or sign-in); required when metrics.host is not loopback: "
        "better DJIGW_CONSOLE__TOKEN or token_file; never logged",
    )
    token_file: Path | None = Field(
        None, description="read the token from this file (a container secret); wins over token"
    )
    read_only: bool = Field(
        False, description="show everything, refuse every action except the emergency stop"
    )
    push_hz: float = Field(10.0, ge=1, le=10, description="state pushes per second to each open page")
    frames: int = Field(500, ge=10, le=5000, description="frames kept per link for the frame inspector")
    journal: int = Field(300, ge=10, le=5000, description="events, requests and replies kept for the log")
    tile_url: str | None = Field(
        None,
        description="map tiles ({z}/{x}/{y} URL, e.g. a local tile server); none: the offline metric grid",
    )
    session_hours: float = Field(12.0, gt=0, le=720, description="a sign-in lasts this long")

    @field_validator("tile_url")
    @classmethod
    def _tiles(cls, v: str | None) -> str | None:
        if v is not None:
            parts = urlsplit(v)
            if parts.scheme not in {"http", "https"} or not parts.hostname:
                raise ValueError("tile_url must be an http:// or https:// URL")
            if not all(k in v for k in ("{z}", "{x}", "{y}")):
                raise ValueError("tile_url must contain {z}, {x} and {y}")
        return v

    @model_validator(mode="after")
    def _token(self) -> ConsoleSettings:
        if self.token_file is not None:
            try:
                text = self.token_file.read_text().strip()
            except OSError as exc:
                raise ValueError(f"cannot read console.token_file: {exc.strerror}") from None
            object.__setattr__(self, "token", SecretStr(text))
        if self.token is not None and len(self.token.get_secret_value()) < MIN_TOKEN_LENGTH:
            raise ValueError(f"console.token must be at least {MIN_TOKEN_LENGTH} characters")
        return self


_device_unions: dict[tuple[type[BaseModel], ...], TypeAdapter[Any]] = {}


def _device(value: Any) -> BaseModel:
    """One ``[[devices]]`` entry, validated by the model of the family its ``type`` names: a union
    discriminated on ``type`` over every family registered now (:mod:`adapters.families`), so a family
    registered after this module was imported is accepted too. Errors keep the union's locations
    (``devices.0.rsdk.bitrate``)."""
    models = families.settings_models()
    union = _device_unions.get(models)
    if union is None:
        discriminated: Any = Annotated[Union[models], Field(discriminator="type")]  # noqa: UP007 - a tuple
        union = _device_unions[models] = TypeAdapter(discriminated)
    device: BaseModel = union.validate_python(value)
    return device


#: One ``[[devices]]`` entry: the settings model of one registered device family (discriminated on ``type``).
DeviceSettings = Annotated[Any, PlainValidator(_device)]


class GatewaySettings(BaseSettings):
    model_config = SettingsConfigDict(
        env_prefix="DJIGW_", env_nested_delimiter="__", extra="forbid", frozen=True, validate_default=True
    )

    gateway_sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._-]+$")
    product: ProductSettings = ProductSettings()
    broker: BrokerSettings = BrokerSettings()
    dispatcher: DispatcherSettings = DispatcherSettings()
    drc: DrcSettings = DrcSettings()
    cloud_control: CloudControlSettings = CloudControlSettings()
    wayline: WaylineSettings = WaylineSettings()
    metrics: MetricsSettings = MetricsSettings()
    console: ConsoleSettings = ConsoleSettings()
    devices: list[DeviceSettings] = Field(default_factory=list, max_length=MAX_SUB_DEVICES)
    video: VideoSettings = VideoSettings()
    osd_period: float = Field(2.0, gt=0, description="periodic osd (0.5 Hz by default, per device override)")
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    log_json: bool = False
    state_dir: Path | None = Field(
        None,
        description="where the crash-safe store keeps what must outlive the process (wayline tasks in "
        "flight); unset: kept in memory only, so a restarted gateway cannot report a task it had started",
    )

    @model_validator(mode="after")
    def _unique(self) -> GatewaySettings:
        sns = [d.sn for d in self.devices]
        if len(set(sns)) != len(sns):
            raise ValueError("device serial numbers must be unique")
        known = set(sns)
        for source in self.video.sources:
            if source.sn not in known:
                raise ValueError(f"video source {source.video_id}: no device with sn {source.sn}")
        vids = [source.video_id for source in self.video.sources]
        if len(set(vids)) != len(vids):
            raise ValueError("video sources must have unique video ids")
        idx = [i for i in (getattr(d, "payload_index", None) for d in self.devices) if i is not None]
        if len(set(idx)) != len(idx):
            raise ValueError("payload_index values must be unique")
        if self.product.announce != "sub_device":
            raise ValueError(
                "product.announce: the gateway announces itself; only a device may say 'gateway'"
            )
        if self.gateway_sn in sns:
            raise ValueError(f"a device may not have the gateway's serial number {self.gateway_sn}")
        domains = {d.sn: d.product.domain for d in self.devices}
        for d in self.devices:
            carrier = getattr(d, "carried_by", None)
            if carrier is not None and domains.get(carrier) != "0":
                raise ValueError(
                    f"devices[{d.sn}].carried_by = {carrier!r}: no aircraft (domain 0) with that sn is "
                    "configured here"
                )
        m, c = self.metrics, self.console
        if m.enabled and c.enabled and c.token is None and not is_loopback(m.host):
            raise ValueError(
                f"the web console needs console.token (DJIGW_CONSOLE__TOKEN or console.token_file) when "
                f"metrics.host ({m.host}) is not loopback; or set console.enabled = false"
            )
        return self

    @classmethod
    def settings_customise_sources(
        cls,
        settings_cls: type[BaseSettings],
        init_settings: PydanticBaseSettingsSource,
        env_settings: PydanticBaseSettingsSource,
        dotenv_settings: PydanticBaseSettingsSource,
        file_secret_settings: PydanticBaseSettingsSource,
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        # environment beats the file (init kwargs carry the TOML document)
        return (env_settings, init_settings)


def _one_line(exc: ValidationError) -> str:
    from gateway.environment import variable_for

    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"]) or "(top level)"
    var = variable_for(err["loc"]) if err["loc"] else None  # the environment wins: name what set it
    source = f" (from ${var})" if var else ""
    more = f" (+{exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
    return f"config error at {where}{source}: {err['msg']}{more}"


def load_settings(path: Path | str | None = None, **overrides: Any) -> GatewaySettings:
    """Read the TOML file (if any), apply environment and ``overrides``; one clear line on error."""
    doc: dict[str, Any] = {}
    if path is not None:
        try:
            doc = tomllib.loads(Path(path).read_text())
        except FileNotFoundError:
            raise ConfigError(f"config file not found: {path}") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"config file {path} is not valid TOML: {exc}") from None
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(doc.get(key), dict):
            doc[key] = {**doc[key], **value}
        else:
            doc[key] = value
    try:
        return GatewaySettings(**doc)
    except ValidationError as exc:
        raise ConfigError(_one_line(exc)) from None


def _is_path(url: str) -> bool:
    """A serial ``url`` that names a file (``/dev/ttyUSB0``, ``./pty``), not a pyserial URL (``socket://``)."""
    return "://" not in url and url != ""


def check_files(settings: GatewaySettings) -> list[str]:
    """Check every file the settings name before anything starts.

    TLS files (``broker.ca_file``, ``cert_file``, ``key_file``) must exist, be readable and load: a
    :class:`ConfigError` names the key and the file. A serial device given as a path is checked too, but
    only refused when it exists and is not a character device (a directory, a regular file): a device
    that is not plugged in yet is not an error (it comes online when it appears), so it is returned
    as a warning line instead."""
    import ssl
    import stat

    b = settings.broker
    for key in ("ca_file", "cert_file", "key_file"):
        path = getattr(b, key)
        if path is None:
            continue
        where = f"config error at broker.{key}: {path}"
        if not path.exists():
            raise ConfigError(f"{where}: not found")
        if not path.is_file():
            raise ConfigError(f"{where}: not a file")
        try:
            path.read_bytes()
        except OSError as exc:
            raise ConfigError(f"{where}: cannot be read ({exc.strerror})") from None
    if b.key_file is not None and b.cert_file is None:
        raise ConfigError("config error at broker.key_file: given without broker.cert_file")
    try:
        if b.ca_file is not None:
            ssl.create_default_context(cafile=str(b.ca_file))
    except (ssl.SSLError, ValueError) as exc:
        raise ConfigError(
            f"config error at broker.ca_file: {b.ca_file}: not a PEM CA certificate ({exc})"
        ) from None
    if b.cert_file is not None:
        try:
            ssl.create_default_context().load_cert_chain(
                str(b.cert_file), str(b.key_file) if b.key_file else None
            )
        except (ssl.SSLError, ValueError) as exc:
            raise ConfigError(
                f"config error at broker.cert_file: {b.cert_file}: certificate and key do not load ({exc})"
            ) from None
    warnings: list[str] = []
    for i, device in enumerate(settings.devices):
        url = getattr(device, "url", None)
        if not isinstance(url, str) or not _is_path(url):
            continue
        path = Path(url)
        where = f"devices[{i}].url: {url}"
        if not path.exists():
            warnings.append(f"{where}: not present (yet): the device comes online when it appears")
            continue
        mode = path.stat().st_mode
        if not stat.S_ISCHR(mode):
            raise ConfigError(f"config error at {where}: not a serial device (a character device or pty)")
    return warnings
