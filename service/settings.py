"""Service settings: the one place they are defined, read from the environment (POSE_*)."""

from __future__ import annotations

import difflib
import re
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Literal, get_args

from pydantic import BeforeValidator, Field, SecretStr, field_validator, model_validator
from pydantic_core import PydanticCustomError
from pydantic_settings import BaseSettings, SettingsConfigDict

from core.compiled_fabrik import MAX_ITERATIONS
from core.text import close_match

#: The shortest ``POSE_DEADLINE_SECONDS``: 10 ms, about one slow lone edit's work (a test
#: sets 30 ms to see some 504s on a busy loop: tests/service/test_faults.py); the deadline
#: also bounds a body's arrival (a 408 past it), which over a network takes longer still.
#: ``1e-9`` was taken, and every request was a 504 (an ops audit).
MIN_DEADLINE_SECONDS = 0.01
#: The most ``POSE_MAX_BATCH_ITEMS`` (``100000000`` was taken, an ops audit): 65,536
#: columnar poses are ~2.4 s of work at the ~27,000 poses/s a worker solves (docs/deploy.md)
#: and a body of ~40 MB; more is several requests.
MAX_BATCH_ITEMS = 65536

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
    if isinstance(value, str) and not all(" " <= c <= "~" for c in value):
        # (an ops audit: 'clé-secrète' was taken, and every /v1 request was a 401: a client
        # sends a header's value as UTF-8 bytes (curl), the server reads them as Latin-1)
        raise PydanticCustomError(
            "non_ascii_api_key",
            "a character that is not printable ASCII: an HTTP header's value is bytes, a "
            "client sends other characters as UTF-8 and the server reads Latin-1, so the "
            "key could never match; use letters, digits and ASCII punctuation only",
        )
    return value


#: An allowed origin as a browser sends it (RFC 6454): scheme and host in lower case,
#: a port only when it is not the scheme's default, no path, not even "/".
_ORIGIN = re.compile(r"[a-z][a-z0-9+.-]*://[^/?#@\s]+")
_DEFAULT_PORTS = {"http": ":80", "https": ":443"}


def origin_problem(entry: str) -> str | None:
    """Why ``entry`` of ``POSE_CORS_ORIGINS`` can never equal a browser's ``Origin`` (the
    CORS middleware compares them exactly), and its fix; None if it can ("*" allows any)."""
    if entry == "*":
        return None
    if entry == "null":  # (sent by sandboxed frames and file:// pages: by anyone who wants)
        return "the 'null' origin is sent by any sandboxed page: allowing it allows anyone"
    if "://" not in entry:
        return f"no scheme: write it as a browser sends it, e.g. 'https://{entry.strip('/')}'"
    scheme, _, rest = entry.partition("://")
    if "/" in rest or "?" in rest or "#" in rest:
        fixed = f"{scheme}://{re.split(r'[/?#]', rest)[0]}"
        return f"a path (even a trailing '/') is never part of an Origin: write {fixed!r}"
    if entry != entry.lower():
        return f"browsers send the scheme and host in lower case: write {entry.lower()!r}"
    if not _ORIGIN.fullmatch(entry):
        return "not an origin (scheme://host[:port], e.g. 'https://editor.example')"
    default = _DEFAULT_PORTS.get(scheme)
    if default and rest.endswith(default):
        fixed = entry[: -len(default)]
        return f"browsers leave the scheme's default port out: write {fixed!r}"
    return None


class Settings(BaseSettings):
    """Every setting is an environment variable with the ``POSE_`` prefix, e.g.
    ``POSE_MODELS_DIR=/srv/models``; lists are JSON (``POSE_CORS_ORIGINS='["http://x"]'``)."""

    model_config = SettingsConfigDict(env_prefix="POSE_", extra="ignore", frozen=True)

    host: str = Field(default="127.0.0.1", min_length=1)  # (empty bound every interface)
    port: int = Field(default=8000, ge=1, le=65535)
    models_dir: Path = BUNDLED_MODELS
    ort_threads: int = Field(default=1, ge=1, le=64, description="onnxruntime intra-op threads.")
    max_batch_items: int = Field(
        default=1024,
        ge=1,
        le=MAX_BATCH_ITEMS,
        description="Items (edits) a batch may hold; 413 past it.",
    )
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
        ge=MIN_DEADLINE_SECONDS,
        le=600,
        allow_inf_nan=False,
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
        allow_inf_nan=False,
        le=3600,
        description="A connection with no request under way is closed after this long: "
        "before its first byte, and between requests (uvicorn's keep-alive timeout).",
    )
    head_timeout_seconds: float = Field(
        default=5.0,
        gt=0,
        allow_inf_nan=False,
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

    @field_validator("cors_origins")
    @classmethod
    def _origins(cls, origins: list[str]) -> list[str]:
        """Refuse an entry no browser's ``Origin`` can equal (a trailing slash, no scheme:
        taken, and every preflight refused with no hint at start; an ops audit)."""
        for i, entry in enumerate(origins):
            problem = origin_problem(entry)
            if problem:
                raise PydanticCustomError(
                    "bad_origin",
                    "entry {index} ({entry}) never matches: {problem}",
                    {"index": i, "entry": repr(entry), "problem": problem},
                )
        return origins

    @model_validator(mode="after")
    def _bodies_fit_the_budget(self) -> Settings:
        """A body the size limit admits must fit the in-flight budget of an idle worker:
        ``POSE_MAX_INFLIGHT_BYTES`` below ``POSE_MAX_BODY_BYTES`` made every chunked body
        (it reserves the whole body limit) and every declared one above the budget a 429
        "retry in 1 s" that could never succeed (an ops audit)."""
        if self.max_inflight_bytes < self.max_body_bytes:
            raise PydanticCustomError(
                "budget_below_body_limit",
                "POSE_MAX_INFLIGHT_BYTES ({inflight}) is below POSE_MAX_BODY_BYTES ({body}): "
                "a body the size limit admits (any chunked one: it reserves the whole body "
                "limit) could never be admitted, a 429 on every retry; raise "
                "POSE_MAX_INFLIGHT_BYTES to at least POSE_MAX_BODY_BYTES (several times it "
                "lets that many such bodies in at once), or lower POSE_MAX_BODY_BYTES",
                {"inflight": self.max_inflight_bytes, "body": self.max_body_bytes},
            )
        return self

    log_level: Annotated[
        Literal["debug", "info", "warning", "error", "critical"],
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

#: ``POSE_*`` names an operator may try for what only an option of ``pose-service`` sets:
#: the worker count is ``--workers`` and no variable (``POSE_WORKERS=2`` started one worker,
#: its warning offering POSE_PORT, a new-user audit). Named in a warning, never refused.
OPTION_ONLY = dict.fromkeys(
    ("POSE_WORKERS", "POSE_WORKER", "POSE_NUM_WORKERS", "POSE_WEB_CONCURRENCY"),
    "the worker count is the --workers option (`pose-service --workers N`), no variable",
)

#: Settings whose values are secrets (``SecretStr``): a refused start names them and never
#: echoes their value (``service.cli``).
SECRET_SETTINGS: frozenset[str] = frozenset(
    name for name, f in Settings.model_fields.items() if SecretStr in get_args(f.annotation)
)


#: Variables Kubernetes injects into a pod for every Service of its namespace while the
#: pod's ``enableServiceLinks`` is on (the default): a Service ``pose-cache`` gives
#: ``POSE_CACHE_SERVICE_HOST``, ``POSE_CACHE_SERVICE_PORT[_<port name>]``,
#: ``POSE_CACHE_PORT`` and ``POSE_CACHE_PORT_<n>_TCP[_PROTO|_PORT|_ADDR]``. Never refused
#: as misspellings (they are no operator's typing, and would break a deploy for a Service
#: someone else made); a Service named ``pose`` would also set ``POSE_PORT`` itself
#: (``tcp://<ip>:<port>``), which an explicit ``env`` entry overrides (deploy/k8s sets it).
_SERVICE_LINK = re.compile(
    r"POSE(_[A-Z0-9_]+)?_(SERVICE_HOST|SERVICE_PORT(_[A-Z0-9_]+)?"
    r"|PORT(_[0-9]+_(TCP|UDP|SCTP)(_(PROTO|PORT|ADDR))?)?)"
)

#: How alike (difflib's ratio, on the names after ``POSE_``) an unknown variable and a
#: setting must be for the variable to be taken as that setting misspelt (refused):
#: POSE_APIKEY 0.92, POSE_LOGLEVEL 0.94, POSE_PROT 0.75; POSE_WORKERS (0.44 to
#: ORT_THREADS) is only named in a warning, POSE_TIMEOUT (0.52) is refused for the word it
#: shares with settings (``_sharing``).
MISSPELT = 0.75


def _known() -> list[str]:
    return [f"POSE_{name.upper()}" for name in Settings.model_fields] + list(OTHER_VARIABLES)


def _unknown(environ: dict[str, str]) -> list[str]:
    known = _known()
    return sorted(k for k in environ if k.upper().startswith("POSE_") and k.upper() not in known)


def _misspelt(key: str, known: list[str]) -> list[str]:
    """The settings ``key`` (an unknown ``POSE_*`` name) stands for, if it is that close:
    its name after ``POSE_`` within :data:`MISSPELT` of a setting's (POSE_APIKEY), or a
    setting's cut at an underscore (POSE_DEADLINE, POSE_KEY, POSE_DIR)
    or lengthened after one (POSE_API_KEY_FILE: no ``_FILE`` form is read), or a name
    sharing a word with a setting's, past the generic ones (:func:`_sharing`:
    POSE_MAX_BODY_SIZE, POSE_DEADLINE_MS, POSE_BATCH_SIZE were only warned of, "did you
    mean POSE_MAX_BODY_BYTES?", and the default stayed in force; an ops audit)."""
    name = key.upper()
    if _SERVICE_LINK.fullmatch(name) or name in OPTION_ONLY:
        return []
    tail = name.removeprefix("POSE_")
    tails = {k.removeprefix("POSE_"): k for k in known}
    cut = [
        k
        for t, k in tails.items()
        if t.startswith(tail + "_") or t.endswith("_" + tail) or tail.startswith(t + "_")
    ]
    if cut:
        return cut
    close = difflib.get_close_matches(tail, list(tails), n=1, cutoff=MISSPELT)
    return [tails[t] for t in close] or _sharing(name, known)


def misspelt_variables(environ: dict[str, str]) -> dict[str, list[str]]:
    """Unknown ``POSE_*`` variables of ``environ`` that misspell a setting, each with the
    settings it may stand for: a start refuses them (``service.cli``). ``POSE_APIKEY=s3cret``
    started the service with /v1 open, a warning its only sign (an ops audit); a typo'd
    limit or timeout likewise left the default in force while its operator believed it set.
    Kubernetes' service-link variables are never counted (:data:`_SERVICE_LINK`)."""
    known = _known()
    out = {}
    for key in _unknown(environ):
        meant = _misspelt(key, known)
        if meant:
            out[key] = meant
    return out


def unknown_variables(environ: dict[str, str]) -> list[str]:
    """The other ``POSE_*`` variables of ``environ`` that are no setting (a start names
    them in a warning: they resemble no setting closely, and share no word with one), each
    with the setting nearest it by spelling if any, or the option that sets what it names
    (:data:`OPTION_ONLY`)."""
    known = _known()
    out = []
    for key in _unknown(environ):
        if _SERVICE_LINK.fullmatch(key.upper()):
            out.append(f"{key} (a Kubernetes Service's link variable?)")
        elif key.upper() in OPTION_ONLY:
            out.append(f"{key} ({OPTION_ONLY[key.upper()]})")
        elif not _misspelt(key, known):
            near = [n for n in [close_match(key.upper(), known)] if n]
            out.append(f"{key}" + (f" (did you mean {' or '.join(near)}?)" if near else ""))
    return out


#: Words too common among the settings' names to say which one a variable meant.
_GENERIC = frozenset({"POSE", "MAX", "SECONDS", "BYTES", "DIR", ""})


def _sharing(key: str, known: list[str]) -> list[str]:
    """The settings (up to 3) whose names share a word with ``key``'s, past the generic
    ones: ``POSE_TIMEOUT`` -> the idle and head timeouts (difflib offered ``POSE_PORT``,
    ``POSE_GRACE`` ``POSE_ACCESS_LOG``: an ops audit, 2026-12-07)."""
    words = set(key.upper().split("_")) - _GENERIC
    return [k for k in known if words & set(k.split("_"))][:3]


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    return Settings()
