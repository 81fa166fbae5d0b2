"""Gateway settings: one pydantic-settings class, read once at start-up and passed down.

Sources, strongest first: ``DJIGW_``-prefixed environment variables (nested with ``__``, e.g.
``DJIGW_BROKER__PASSWORD``), then the TOML file given with ``--config``. Secrets have no defaults
and are ``SecretStr`` so they never reach a log line or an error message. No import-time singleton.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SecretStr,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource, SettingsConfigDict

from adapters.config import ProductSettings
from adapters.osdk.config import OsdkDeviceSettings
from adapters.robomaster.config import RobomasterDeviceSettings
from adapters.rsdk.config import RsdkDeviceSettings
from schemas.status import MAX_SUB_DEVICES

__all__ = [
    "BrokerSettings",
    "ConfigError",
    "DispatcherSettings",
    "DrcSettings",
    "GatewaySettings",
    "MetricsSettings",
    "ProductSettings",
    "RsdkDeviceSettings",
    "load_settings",
]

_STRICT = ConfigDict(extra="forbid", frozen=True)


class ConfigError(ValueError):
    """A configuration that cannot run; the message is one line naming the field."""


class BrokerSettings(BaseModel):
    model_config = _STRICT
    url: str = Field(
        "mqtt://127.0.0.1:1883", description="mqtt://, mqtts://, ws:// or wss:// host:port[/path]"
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
    inbound_queue: int = Field(
        1000, ge=10, description="received messages held for the loop; more are dropped"
    )
    max_payload: int = Field(65536, ge=1024, description="inbound payloads larger than this are refused")

    @field_validator("url")
    @classmethod
    def _url(cls, v: str) -> str:
        parts = urlsplit(v)
        if parts.scheme not in {"mqtt", "mqtts", "ws", "wss", "tcp", "ssl"}:
            raise ValueError("scheme must be mqtt://, mqtts://, ws:// or wss://")
        if not parts.hostname:
            raise ValueError("missing host")
        return v

    @property
    def transport(self) -> Literal["tcp", "websockets"]:
        return "websockets" if urlsplit(self.url).scheme in {"ws", "wss"} else "tcp"

    @property
    def tls(self) -> bool:
        return urlsplit(self.url).scheme in {"mqtts", "wss", "ssl"}

    @property
    def host(self) -> str:
        return urlsplit(self.url).hostname or ""

    @property
    def port(self) -> int:
        parts = urlsplit(self.url)
        if parts.port:
            return parts.port
        return {"mqtt": 1883, "tcp": 1883, "mqtts": 8883, "ssl": 8883, "ws": 80, "wss": 443}[parts.scheme]

    @property
    def ws_path(self) -> str:
        return urlsplit(self.url).path or "/mqtt"


class DispatcherSettings(BaseModel):
    model_config = _STRICT
    request_timeout: float = Field(
        1.0, gt=0, le=2.5, description="device deadline; the reply is always < 3 s"
    )
    reply_cache_seconds: float = Field(30.0, ge=0)
    require_authority: bool = Field(
        True, description="camera/gimbal/flight methods need a prior *_authority_grab"
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


class MetricsSettings(BaseModel):
    """The HTTP endpoint for Prometheus (``/metrics``), health checks (``/healthz``) and ``dji-gateway
    status`` (``/status``)."""

    model_config = _STRICT
    enabled: bool = Field(True, description="serve /metrics, /healthz and /status")
    host: str = Field(
        "127.0.0.1", description="listen address; 0.0.0.0 in a container that Prometheus scrapes"
    )
    port: int = Field(9108, ge=0, le=65535, description="HTTP port (0: any free port, logged at start)")


DeviceSettings = Annotated[
    RsdkDeviceSettings | OsdkDeviceSettings | RobomasterDeviceSettings, Field(discriminator="type")
]


class GatewaySettings(BaseSettings):
    model_config = SettingsConfigDict(
        env_prefix="DJIGW_", env_nested_delimiter="__", extra="forbid", frozen=True, validate_default=True
    )

    gateway_sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._-]+$")
    product: ProductSettings = ProductSettings()
    broker: BrokerSettings = BrokerSettings()
    dispatcher: DispatcherSettings = DispatcherSettings()
    drc: DrcSettings = DrcSettings()
    metrics: MetricsSettings = MetricsSettings()
    devices: list[DeviceSettings] = Field(default_factory=list, max_length=MAX_SUB_DEVICES)
    osd_period: float = Field(2.0, gt=0, description="periodic osd (0.5 Hz by default, per device override)")
    log_level: Literal["DEBUG", "INFO", "WARNING", "ERROR"] = "INFO"
    log_json: bool = False

    @model_validator(mode="after")
    def _unique(self) -> GatewaySettings:
        sns = [d.sn for d in self.devices]
        if len(set(sns)) != len(sns):
            raise ValueError("device serial numbers must be unique")
        idx = [i for i in (getattr(d, "payload_index", None) for d in self.devices) if i is not None]
        if len(set(idx)) != len(idx):
            raise ValueError("payload_index values must be unique")
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
