#!/usr/bin/env bash
# Container smoke test: build the service image, run it, wait until it is ready, POST a
# real /v1/solve and check the answer, check the image's properties and a graceful stop,
# then remove the container (on any exit). Meant for `.ci/run`; runs as root on a fresh
# machine too (it installs podman/runc/debootstrap when needed).
#
#   bash docker/smoke.sh
#
# Engine: docker when its daemon answers, else podman. When the base image cannot be
# pulled (no registry reachable), a stand-in Debian bookworm base with python3 is made
# with debootstrap and imported once as localhost/marionette-base:bookworm (kept, so later
# runs skip it). Figures (build time, image size, start-to-ready, solve latency) are
# printed at the end, as `SMOKE <name>=<value>` lines.
#
# Environment knobs (all optional):
#   SMOKE_ENGINE=docker|podman   force an engine
#   SMOKE_IMAGE                  tag to build          (localhost/marionette:smoke)
#   BASE_IMAGE                   base for both stages  (python:3.11-slim-bookworm)
#   SMOKE_STANDIN_IMAGE          stand-in base tag     (localhost/marionette-base:bookworm)
#   DEBIAN_MIRROR                for debootstrap       (debootstrap's own default)
#   SMOKE_NO_CACHE=1             build without the layer cache (a cold build)
#   SMOKE_BUILD_TIMEOUT          seconds               (1800)
#   SMOKE_READY_TIMEOUT          seconds               (240)
#   SMOKE_SOLVES                 timed /v1/solve calls (20)
#   SMOKE_MAX_ERROR              metres, default reach (0.10)
#   SMOKE_PORT                   host port             (a free one)
# The built image and the stand-in base are kept: they are the layer cache of the next run.
set -Eeuo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

IMAGE="${SMOKE_IMAGE:-localhost/marionette:smoke}"
BASE_IMAGE="${BASE_IMAGE:-python:3.11-slim-bookworm}"
STANDIN_IMAGE="${SMOKE_STANDIN_IMAGE:-localhost/marionette-base:bookworm}"
DEBIAN_MIRROR="${DEBIAN_MIRROR:-}"
BUILD_TIMEOUT="${SMOKE_BUILD_TIMEOUT:-1800}"
READY_TIMEOUT="${SMOKE_READY_TIMEOUT:-240}"
SOLVES="${SMOKE_SOLVES:-20}"
MAX_ERROR="${SMOKE_MAX_ERROR:-0.10}"
CA_BUNDLE="${SMOKE_CA_BUNDLE:-/etc/ssl/certs/ca-certificates.crt}"
NAME="marionette-smoke-$$"
NAME_OVERRIDE="marionette-smoke-models-$$"
PY="$(command -v python3 || command -v python)"

log() { printf '[smoke %(%H:%M:%S)T] %s\n' -1 "$*" >&2; }
die() { log "FAIL: $*"; exit 1; }
figure() { printf 'SMOKE %s=%s\n' "$1" "$2"; }
now() { date +%s.%N; }
elapsed() { "$PY" -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$1" "$2"; }

# --------------------------------------------------------------------------- engine
APT_UPDATED=0
apt_install() {
    [[ $(id -u) -eq 0 ]] || die "need root to install $* (or install them yourself)"
    command -v apt-get >/dev/null || die "no apt-get to install $*"
    if [[ $APT_UPDATED -eq 0 ]]; then
        timeout 300 apt-get update -qq >&2 || die "apt-get update failed"
        APT_UPDATED=1
    fi
    log "installing $*"
    DEBIAN_FRONTEND=noninteractive timeout 900 apt-get install -y -qq "$@" >&2 \
        || die "apt-get install $* failed"
}

ENGINE="${SMOKE_ENGINE:-}"
if [[ -z $ENGINE ]]; then
    if command -v docker >/dev/null && timeout 20 docker info >/dev/null 2>&1; then
        ENGINE=docker
    else
        ENGINE=podman
    fi
fi

ENG=("$ENGINE")
BUILD_FLAGS=()
if [[ $ENGINE == podman ]]; then
    missing=()
    command -v podman >/dev/null || missing+=(podman)
    command -v runc >/dev/null || missing+=(runc)
    [[ ${#missing[@]} -eq 0 ]] || apt_install "${missing[@]}"
    # No systemd, no delegated cgroups, default ulimits not raisable: see the file.
    export CONTAINERS_CONF="${CONTAINERS_CONF:-$ROOT/docker/containers.conf}"
    ENG=(podman --runtime runc)
    # OCI format would drop HEALTHCHECK; build layers are cached by default.
    BUILD_FLAGS+=(--format docker)
else
    export DOCKER_BUILDKIT=1
fi
log "engine: ${ENG[*]} ($("${ENG[@]}" --version 2>/dev/null | head -n1))"

# --------------------------------------------------------------------------- cleanup
cleanup() {
    local rc=$?
    set +e
    for c in "$NAME" "$NAME_OVERRIDE"; do
        if "${ENG[@]}" container inspect "$c" >/dev/null 2>&1; then
            if [[ $rc -ne 0 && $c == "$NAME" ]]; then
                log "container logs ($c, last 60 lines):"
                "${ENG[@]}" logs --tail 60 "$c" >&2 2>&1
            fi
            timeout 60 "${ENG[@]}" rm -f -t 5 "$c" >/dev/null 2>&1 \
                || timeout 60 "${ENG[@]}" rm -f "$c" >/dev/null 2>&1
        fi
    done
    [[ -n ${WORK:-} ]] && rm -rf "$WORK"
    if [[ $rc -eq 0 ]]; then log "OK"; else log "smoke failed (exit $rc)"; fi
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
WORK="$(mktemp -d)"

image_exists() {
    if [[ $ENGINE == podman ]]; then podman image exists "$1"; else docker image inspect "$1" >/dev/null 2>&1; fi
}

# --------------------------------------------------------------------------- base image
# podman may have no unqualified-search registries: spell out Docker Hub's short names.
if [[ $ENGINE == podman ]]; then
    first="${BASE_IMAGE%%/*}"
    if [[ $BASE_IMAGE != */* ]]; then
        BASE_IMAGE="docker.io/library/$BASE_IMAGE"
    elif [[ $first != *[.:]* && $first != localhost ]]; then
        BASE_IMAGE="docker.io/$BASE_IMAGE"
    fi
fi
if image_exists "$BASE_IMAGE"; then
    log "base image $BASE_IMAGE present"
elif timeout 180 "${ENG[@]}" pull -q "$BASE_IMAGE" >/dev/null 2>&1; then
    log "pulled base image $BASE_IMAGE"
else
    log "cannot pull $BASE_IMAGE: using the stand-in $STANDIN_IMAGE"
    BASE_IMAGE="$STANDIN_IMAGE"
    if image_exists "$STANDIN_IMAGE"; then
        log "stand-in base present (cached)"
    else
        command -v debootstrap >/dev/null || apt_install debootstrap
        [[ $(id -u) -eq 0 ]] || die "debootstrap needs root"
        t0=$(now)
        rootfs="$WORK/rootfs"
        log "debootstrap bookworm ${DEBIAN_MIRROR:+from $DEBIAN_MIRROR }(minbase + python3)"
        timeout 1200 debootstrap --variant=minbase \
            --include=python3,python3-venv,python3-pip,ca-certificates \
            bookworm "$rootfs" ${DEBIAN_MIRROR:+"$DEBIAN_MIRROR"} >"$WORK/debootstrap.log" 2>&1 \
            || { tail -n 30 "$WORK/debootstrap.log" >&2; die "debootstrap failed"; }
        # What the official slim image leaves out too: apt caches, docs, man pages, locales.
        rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/* \
            "$rootfs"/usr/share/doc/* "$rootfs"/usr/share/man/* "$rootfs"/usr/share/info/* \
            "$rootfs"/usr/share/locale/*
        tar -C "$rootfs" -c . | timeout 600 "${ENG[@]}" import \
            --change 'CMD ["/bin/bash"]' --change 'ENV LANG=C.UTF-8' - "$STANDIN_IMAGE" >/dev/null \
            || die "import of the stand-in base failed"
        rm -rf "$rootfs"
        figure standin_base_seconds "$(elapsed "$t0" "$(now)")"
    fi
fi

# --------------------------------------------------------------------------- build
# Package installs inside the build reach the index only through the host network, and
# behind a TLS-inspecting proxy only with the host's CA bundle: passed as a build secret,
# mounted for the pip steps only, never stored in a layer.
BUILD_FLAGS+=(--network host --build-arg "BASE_IMAGE=$BASE_IMAGE" -f docker/Dockerfile -t "$IMAGE")
[[ -s $CA_BUNDLE ]] && BUILD_FLAGS+=(--secret "id=cacert,src=$CA_BUNDLE")
[[ ${PIP_INDEX_URL:-} == http* ]] && BUILD_FLAGS+=(--build-arg "PIP_INDEX_URL=$PIP_INDEX_URL")
[[ ${SMOKE_NO_CACHE:-0} == 1 ]] && BUILD_FLAGS+=(--no-cache)
log "building $IMAGE (base $BASE_IMAGE)"
t0=$(now)
timeout "$BUILD_TIMEOUT" "${ENG[@]}" build "${BUILD_FLAGS[@]}" . >"$WORK/build.log" 2>&1 \
    || { tail -n 60 "$WORK/build.log" >&2; die "image build failed (or timed out after ${BUILD_TIMEOUT}s)"; }
figure build_seconds "$(elapsed "$t0" "$(now)")"
size_bytes="$("${ENG[@]}" image inspect --format '{{.Size}}' "$IMAGE")"
figure image_size_mb "$("$PY" -c "import sys; print(round(int(sys.argv[1]) / 1e6))" "$size_bytes")"

# --------------------------------------------------------------------------- image properties
user="$("${ENG[@]}" image inspect --format '{{.Config.User}}' "$IMAGE")"
[[ -n $user && ${user%%:*} != 0 && ${user%%:*} != root ]] || die "image runs as root (User='$user')"
hc="$("${ENG[@]}" image inspect --format '{{json .Config.Healthcheck}}' "$IMAGE")"
[[ $hc == *healthcheck.py* ]] || die "image has no HEALTHCHECK (got: $hc)"
# shellcheck disable=SC2016  # expanded by the container's shell, not here
"${ENG[@]}" run --rm --entrypoint /bin/sh "$IMAGE" -c '
    set -e
    for tool in gcc cc g++ make curl wget; do
        if command -v "$tool" >/dev/null; then echo "runtime image has $tool" >&2; exit 1; fi
    done
    python - <<EOF
import importlib.util
bad = [m for m in ("torch", "trainer", "pytest") if importlib.util.find_spec(m)]
assert not bad, f"runtime image has {bad}"
for m in ("numpy", "onnxruntime", "fastapi", "uvicorn", "service"):
    assert importlib.util.find_spec(m), f"runtime image lacks {m}"
EOF
' 2>"$WORK/props.err" || { cat "$WORK/props.err" >&2; die "runtime image content check failed"; }
log "image: user $user, healthcheck set, no compilers/curl/torch"

# --------------------------------------------------------------------------- run
PORT="${SMOKE_PORT:-$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')}"
BASE_URL="http://127.0.0.1:$PORT"
# As in deploy/k8s: read-only root, a tmpfs /tmp, no capabilities, no privilege gain.
SEC_FLAGS=(--read-only --tmpfs /tmp --cap-drop ALL --security-opt no-new-privileges)
# podman runs health checks from systemd timers; there is no systemd here (the check is
# run by hand below instead).
[[ $ENGINE == podman ]] && SEC_FLAGS+=(--health-interval disable)
t0=$(now)
"${ENG[@]}" run -d --name "$NAME" -p "127.0.0.1:$PORT:8000" "${SEC_FLAGS[@]}" "$IMAGE" >/dev/null 2>"$WORK/run.err" \
    || { cat "$WORK/run.err" >&2; die "container did not start"; }
log "container $NAME on $BASE_URL"

http_status() {  # URL -> prints the HTTP status (000 when no answer)
    "$PY" - "$1" <<'EOF'
import sys, urllib.request, urllib.error
try:
    with urllib.request.urlopen(sys.argv[1], timeout=3) as r:
        print(r.status)
except urllib.error.HTTPError as e:
    print(e.code)
except Exception:
    print("000")
EOF
}

http_body() {  # URL -> prints the response body (any status), at most 500 characters
    "$PY" - "$1" <<'EOF'
import sys, urllib.request, urllib.error
try:
    with urllib.request.urlopen(sys.argv[1], timeout=3) as r:
        body = r.read()
except urllib.error.HTTPError as e:
    body = e.read()
except Exception as e:
    body = repr(e).encode()
print(body.decode(errors="replace")[:500])
EOF
}

running() { [[ "$("${ENG[@]}" container inspect --format '{{.State.Running}}' "$1" 2>/dev/null)" == true ]]; }

deadline=$((SECONDS + READY_TIMEOUT))
saw_503=0
while :; do
    status="$(http_status "$BASE_URL/v2/health/ready")"
    [[ $status == 200 ]] && break
    if [[ $status == 503 ]]; then
        saw_503=1
        # The service gives up for good on a load/verify/warm-up failure and says why.
        body="$(http_body "$BASE_URL/v2/health/ready")"
        detail="$("$PY" -c 'import json, sys; print((json.loads(sys.argv[1]) or {}).get("detail") or "")' "$body" 2>/dev/null || true)"
        [[ -z $detail ]] || die "the service cannot get ready: $detail"
    fi
    running "$NAME" || die "container exited (code $("${ENG[@]}" container inspect --format "{{.State.ExitCode}}" "$NAME")) before it was ready"
    ((SECONDS < deadline)) \
        || die "not ready after ${READY_TIMEOUT}s: $status $(http_body "$BASE_URL/v2/health/ready")"
    sleep 0.25
done
figure start_to_ready_seconds "$(elapsed "$t0" "$(now)")"
[[ $(http_status "$BASE_URL/v2/health/live") == 200 ]] || die "/v2/health/live is not 200"
log "ready (saw 503 while warming up: $saw_503); live 200"
# The image's own HEALTHCHECK command, run the way the engine runs it.
"${ENG[@]}" exec "$NAME" /opt/venv/bin/python /opt/marionette/healthcheck.py \
    || die "the HEALTHCHECK command fails in the running container"
[[ $("${ENG[@]}" exec "$NAME" id -u) != 0 ]] || die "the service runs as root"

# --------------------------------------------------------------------------- solve
"$PY" - "$BASE_URL" "$SOLVES" "$MAX_ERROR" >"$WORK/solve.out" <<'EOF' || { cat "$WORK/solve.out" >&2; die "/v1/solve check failed"; }
import json, math, statistics, sys, time, urllib.error, urllib.request

base, n_timed, max_error = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])


def call(method, path, body=None):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(base + path, data=data, method=method,
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read() or b"null")
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode(errors="replace")


# A rest pose: metres, +Y up, facing +Z, the character's left is +X (service/skeleton.py),
# arms hanging with soft elbows. Used unless the service offers one at GET /v1/skeleton.
half = {
    "collar": (0.04, 1.40, 0.00), "shoulder": (0.17, 1.40, 0.00), "elbow": (0.19, 1.12, -0.01),
    "wrist": (0.20, 0.87, 0.03), "hip": (0.09, 0.90, 0.00), "knee": (0.10, 0.50, 0.01),
    "ankle": (0.10, 0.08, -0.02), "foot": (0.11, 0.02, 0.10),
}
pose = {"pelvis": [0.0, 0.95, 0.0], "spine1": [0.0, 1.05, 0.0], "spine2": [0.0, 1.20, 0.0],
        "neck": [0.0, 1.45, 0.0], "head": [0.0, 1.60, 0.02]}
for part, (x, y, z) in half.items():
    pose[f"left_{part}"] = [x, y, z]
    pose[f"right_{part}"] = [-x, y, z]
source = "constructed rest pose"

# The service's own skeleton: joint names, parents and its reference bone lengths. The
# rest pose above is rebuilt root outwards along the same bone directions with those lengths.
status, skel = call("GET", "/v1/skeleton")
if status == 200 and isinstance(skel, dict):
    assert sorted(skel["joints"]) == sorted(pose), f"skeleton joints differ: {skel['joints']}"
    parents, lengths = skel["parents"], skel.get("reference_bone_lengths") or {}
    if len(lengths) == 20:
        rebuilt = {}
        for name in skel["joints"]:  # parents precede children
            parent = parents[name]
            if parent is None:
                rebuilt[name] = list(pose[name])
                continue
            d = [c - p for c, p in zip(pose[name], pose[parent])]
            norm = math.sqrt(sum(c * c for c in d))
            rebuilt[name] = [p + c / norm * lengths[name] for p, c in zip(rebuilt[parent], d)]
        pose = rebuilt
        source = "rest pose with the bone lengths of GET /v1/skeleton"
else:
    print(f"GET /v1/skeleton: HTTP {status}; using the constructed pose", file=sys.stderr)
assert len(pose) == 21, len(pose)

# Reach forward with the left hand: well inside the arm's reach from the shoulder.
shoulder = pose["left_shoulder"]
target = [shoulder[0] - 0.02, shoulder[1] - 0.30, shoulder[2] + 0.30]
body = {"pose": pose, "targets": [{"joint": "left_wrist", "position": target}]}

status, answer = call("POST", "/v1/solve", body)
assert status == 200, f"/v1/solve: HTTP {status}: {answer}"
out = answer["pose"]
assert isinstance(out, dict) and sorted(out) == sorted(pose), f"joints: {sorted(out)}"
for name, xyz in out.items():
    assert len(xyz) == 3 and all(math.isfinite(float(c)) for c in xyz), (name, xyz)
(t,) = answer["targets"]
assert t["joint"] == "left_wrist", t
reported = float(t["error"])
actual = math.dist(out["left_wrist"], target)
# The default ("soft") reach is the learned solver's answer alone: near, not exact. It must
# at least have gone most of the way from where the wrist was.
start = math.dist(pose["left_wrist"], target)
assert reported <= max_error, f"target error {reported:.4f} m > {max_error} m: {t}"
assert reported <= 0.5 * start, f"target error {reported:.4f} m from {start:.4f} m away"
assert abs(actual - reported) <= 1e-3, f"reported error {reported} but measured {actual}"
bone_error = float(answer.get("max_bone_length_error", 0.0))
assert bone_error <= 0.01, f"bone lengths off by {bone_error:.3%}"
print(f"pose source: {source}; target error {reported * 1000:.1f} mm, "
      f"reached={t.get('reached')}, bone-length error {bone_error:.2e}", file=sys.stderr)

# Exact reach: refined until within tolerance.
exact = dict(body, options={"reach": "exact"})
status, answer = call("POST", "/v1/solve", exact)
assert status == 200, f"/v1/solve exact: HTTP {status}: {answer}"
(te,) = answer["targets"]
assert te["reached"], f"exact reach: {te}"
assert float(te["error"]) <= 1e-3 + 1e-6, f"exact reach: {te}"
assert float(answer["max_bone_length_error"]) <= 0.01, answer["max_bone_length_error"]

times = []
for _ in range(n_timed):
    t0 = time.perf_counter()
    status, _ = call("POST", "/v1/solve", body)
    times.append((time.perf_counter() - t0) * 1000)
    assert status == 200, status
times.sort()
p95 = times[min(len(times) - 1, math.ceil(0.95 * len(times)) - 1)]
print(f"solve_latency_ms_median={statistics.median(times):.1f}")
print(f"solve_latency_ms_p95={p95:.1f}")
print(f"target_error_mm={reported * 1000:.1f}")
print(f"exact_target_error_mm={float(te['error']) * 1000:.2f}")
EOF
while IFS='=' read -r k v; do figure "$k" "$v"; done <"$WORK/solve.out"

# --------------------------------------------------------------------------- graceful stop
t0=$(now)
timeout 60 "${ENG[@]}" stop -t 30 "$NAME" >/dev/null 2>&1 || die "stop failed"
code="$("${ENG[@]}" container inspect --format '{{.State.ExitCode}}' "$NAME")"
figure stop_seconds "$(elapsed "$t0" "$(now)")"
# 0, or 143 when the server re-raises SIGTERM after its graceful shutdown; 137 = SIGKILL.
[[ $code == 0 || $code == 143 ]] || die "exit code $code after SIGTERM (137 = killed: no graceful shutdown)"
logs="$("${ENG[@]}" logs "$NAME" 2>&1 || true)"
[[ ${logs,,} == *"shutting down"* || ${logs,,} == *shutdown* ]] || log "warning: no shutdown line in the logs"
log "graceful stop: exit $code"

# --------------------------------------------------------------------------- models override
# An empty directory mounted over the bundled models must be what the service loads, so it
# must never become ready: it exits, or stays live with ready != 200.
PORT2="$("$PY" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
BASE_URL="http://127.0.0.1:$PORT2"
mkdir -m 755 "$WORK/empty-models"
"${ENG[@]}" run -d --name "$NAME_OVERRIDE" -p "127.0.0.1:$PORT2:8000" -v "$WORK/empty-models:/opt/marionette/models:ro" \
    "${SEC_FLAGS[@]}" "$IMAGE" >/dev/null 2>"$WORK/run2.err" || { cat "$WORK/run2.err" >&2; die "second container did not start"; }
deadline=$((SECONDS + 90))
verdict=""
while [[ -z $verdict ]]; do
    if ! running "$NAME_OVERRIDE"; then
        verdict="exited with $("${ENG[@]}" container inspect --format '{{.State.ExitCode}}' "$NAME_OVERRIDE")"
        [[ $verdict != "exited with 0" ]] || die "models override: exited 0 without models"
        break
    fi
    ready="$(http_status "$BASE_URL/v2/health/ready")"
    [[ $ready == 200 ]] && die "models override ignored: ready with an empty models directory"
    if [[ $(http_status "$BASE_URL/v2/health/live") == 200 && $ready != 000 ]]; then
        sleep 3  # give it time to (wrongly) turn ready before judging
        [[ $(http_status "$BASE_URL/v2/health/ready") == 200 ]] \
            && die "models override ignored: ready with an empty models directory"
        verdict="live, ready=$ready"
    fi
    ((SECONDS < deadline)) || die "models override: neither exited nor answered in 90 s"
    sleep 0.5
done
log "models volume override honoured (empty models dir: $verdict)"
