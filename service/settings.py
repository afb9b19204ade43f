"""Service settings: the one place they are defined, read from the environment (POSE_*)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal, get_args

from pydantic import BeforeValidator, Field, SecretStr
from pydantic_core import PydanticCustomError
from pydantic_settings import BaseSettings, SettingsConfigDict

from core.compiled_fabrik import MAX_ITERATIONS
from core.text import close_match

#: The models shipped with the repository (``<repo>/models``).
BUNDLED_MODELS = Path(__file__).resolve().parent.parent / "models"


def _not_blank(value: object) -> object:
    """Refuse an API key that is empty or only blanks, or that has blanks around it. An
    empty ``POSE_API_KEY`` turned authentication off without a word (an ops audit): a
    deployment whose secret came out empty (a secretKeyRef to an empty value,
    ``POSE_API_KEY=$UNSET_VARIABLE``) served /v1 to anyone while its operator believed it
    guarded. A key of blanks, or with blanks around it, no client can send (HTTP parsers
    skip the blanks around a header's value), so every /v1 request would be a 401. Refused
    as other settings are (``service.cli``: one ``start_refused`` line, exit 2); unset the
    variable to serve /v1 without a key."""
    if isinstance(value, str) and not value.strip():
        raise PydanticCustomError(
            "blank_api_key",
            "empty or only blanks (an empty key left /v1 open, blanks no client can send): "
            "set the key, or unset POSE_API_KEY to serve /v1 without one",
        )
    if isinstance(value, str) and value != value.strip():
        # (a Secret made from a file that ends in a newline: the key no client sends, as a
        # header's value arrives without them, and every /v1 request a 401 with no hint)
        raise PydanticCustomError(
            "padded_api_key",
            "blanks or a newline before or after the key (a Secret made from a file that "
            "ends in a newline?): no client sends them; remove them",
        )
    return value


class Settings(BaseSettings):
    """Every setting is an environment variable with the ``POSE_`` prefix, e.g.
    ``POSE_MODELS_DIR=/srv/models``; lists are JSON (``POSE_CORS_ORIGINS='["http://x"]'``)."""

    model_config = SettingsConfigDict(env_prefix="POSE_", extra="ignore", frozen=True)

    host: str = Field(default="127.0.0.1", min_length=1)  # (empty bound every interface)
    port: int = Field(default=8000, ge=1, le=65535)
    models_dir: Path = BUNDLED_MODELS
    ort_threads: int = Field(default=1, ge=1, le=64, description="onnxruntime intra-op threads.")
    max_batch_items: int = Field(default=1024, ge=1)
    max_body_bytes: int = Field(default=8 * 1024 * 1024, ge=1024)
    max_concurrency: int = Field(
        default=64,
        ge=1,
        description="Admitted /v1 POST requests in flight per worker; 429 past it.",
    )
    max_inflight_bytes: int = Field(
        default=64 * 1024 * 1024,
        ge=1024,
        description="Request bodies (declared or streamed, any route's) held at once per "
        "worker; 429 past it.",
    )
    decode_memory_bytes: int = Field(
        default=160 * 1024 * 1024,
        ge=1024 * 1024,
        description="Memory a worker's request bodies may take decoded at once (each of "
        "64 KiB or more priced by its shape, service.decoded); a body that alone needs "
        "more is a 413, others wait for it within the deadline (504 past it).",
    )
    deadline_seconds: float = Field(
        default=2.0,
        gt=0,
        le=600,
        description="Wall time one request's work may take; 504 past it (a batch whose "
        "items are all done is answered).",
    )
    max_unsent_bytes: int = Field(
        default=64 * 1024 * 1024,
        ge=1024,
        description="Answers held per worker for clients that do not take them; past it, "
        "the longest-waiting connections are closed (service.transport).",
    )
    max_connections: int = Field(
        default=1024,
        ge=1,
        description="Open connections per worker; past it a new one is answered 503 "
        "(too-many-connections) and closed (service.transport).",
    )
    idle_timeout_seconds: float = Field(
        default=5.0,
        gt=0,
        le=3600,
        description="A connection with no request under way is closed after this long: "
        "before its first byte, and between requests (uvicorn's keep-alive timeout).",
    )
    head_timeout_seconds: float = Field(
        default=5.0,
        gt=0,
        le=600,
        description="Time a request's line and headers may take from their first byte; "
        "past it, 408 (head-timeout) and the connection is closed.",
    )
    compute_threads: int = Field(
        default=2, ge=1, le=64, description="Threads solving or parsing big bodies at once."
    )
    shutdown_grace_seconds: int = Field(
        default=10, ge=0, le=3600, description="After SIGTERM, time to finish in-flight work."
    )
    cors_origins: list[str] = Field(default_factory=list)
    api_key: Annotated[SecretStr | None, BeforeValidator(_not_blank)] = Field(
        default=None,
        description="The key /v1 requests must send (X-API-Key or Authorization: Bearer); "
        "unset, /v1 is open. Empty, blank or with blanks around it refuses the start.",
    )
    composition_passes: int = Field(
        default=1,
        ge=1,
        le=8,
        description="Cycles through the solvers of a composed set; models without "
        "`serving.delta` only (the shipped ones answer in deltas: ignored, with a warning).",
    )
    composition: Literal["reencode", "sequential"] = Field(
        default="reencode",
        description="reencode: paste solved targets and re-encode between solvers; "
        "sequential: the paper's plain chain of solvers.",
    )
    composition_projections: int = Field(
        default=1,
        ge=0,
        le=8,
        description="Paste-all-targets-and-re-encode rounds at the end; models without "
        "`serving.delta` only (the shipped ones answer in deltas: ignored, with a warning).",
    )
    fabrik_max_iterations: int = Field(default=MAX_ITERATIONS, ge=1, le=10_000)
    solve_mirror: bool | None = Field(
        default=None,
        description="Whether neural passes also solve the mirror image unless a request "
        "says (`options.mirror`); unset: the models' `serving.solve_mirror`. `false` halves "
        "the networks' work for a deployment that wants speed more than the last tenth of "
        "a millimetre.",
    )
    log_level: Annotated[
        Literal["debug", "info", "warning", "error"],
        BeforeValidator(lambda v: v.lower() if isinstance(v, str) else v),  # INFO too
    ] = "info"
    access_log: bool = True


#: prometheus_client's multiprocess mode: where set (before the client library is
#: imported), every process writes its metrics into files in this folder, and a scrape of
#: any of them reads the sum over all (``service.metrics``; ``pose-service --workers N``).
SHARED_DIR = "PROMETHEUS_MULTIPROC_DIR"

#: ``POSE_*`` variables read by something else than the settings (a start does not call
#: them unknown): the image's health check's route (docker/healthcheck.py).
OTHER_VARIABLES = ("POSE_HEALTH_PATH",)

#: Settings whose values are secrets (``SecretStr``): a refused start names them and never
#: echoes their value (``service.cli``).
SECRET_SETTINGS: frozenset[str] = frozenset(
    name for name, f in Settings.model_fields.items() if SecretStr in get_args(f.annotation)
)


def unknown_variables(environ: dict[str, str]) -> list[str]:
    """``POSE_*`` variables of ``environ`` that are no setting (a typo is ignored by the
    settings: ``POSE_DEADLINE=9`` left the deadline at 2 s, an ops audit), each with the
    setting nearest it."""
    known = [f"POSE_{name.upper()}" for name in Settings.model_fields] + list(OTHER_VARIABLES)
    out = []
    for key in sorted(k for k in environ if k.upper().startswith("POSE_")):
        if key.upper() not in known:
            near = close_match(key.upper(), known)
            out.append(f"{key}" + (f" (did you mean {near}?)" if near else ""))
    return out


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
