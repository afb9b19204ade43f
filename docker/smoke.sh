#!/usr/bin/env bash
# The container check, bootstrap half: a container engine and a base image. The checks
# themselves (build, image content, run as Kubernetes does, ready, solve, character routes,
# graceful stop, models override) are Python: tests/deploy/test_container.py.
#
#   bash docker/smoke.sh              bootstrap, then pytest on tests/deploy/test_container.py
#   bash docker/smoke.sh --bootstrap  bootstrap only (.ci/run; `make test` then runs the test)
#
# Engine: docker when its daemon answers, else podman (podman and runc installed with apt
# when missing; run with docker/containers.conf: no systemd here). Base: BASE_IMAGE
# (python:3.11-slim-bookworm) when present or pullable, else a stand-in made once with
# debootstrap (bookworm minbase + python3) and kept as SMOKE_STANDIN_IMAGE
# (localhost/marionette-base:bookworm). DEBIAN_MIRROR: debootstrap's mirror.
set -Eeuo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
BASE_IMAGE="${BASE_IMAGE:-python:3.11-slim-bookworm}"
STANDIN="${SMOKE_STANDIN_IMAGE:-localhost/marionette-base:bookworm}"
log() { printf '[smoke %(%H:%M:%S)T] %s\n' -1 "$*" >&2; }
die() { log "FAIL: $*"; exit 1; }
apt_install() {
    [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null || die "install $* (needs root + apt)"
    log "installing $*"
    { timeout 300 apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
        timeout 900 apt-get install -y -qq "$@"; } >&2 || die "apt-get install $* failed"
}

ENGINE="${SMOKE_ENGINE:-}"
if [[ -z $ENGINE ]]; then
    ENGINE=podman
    command -v docker >/dev/null && timeout 20 docker info >/dev/null 2>&1 && ENGINE=docker
fi
ENG=("$ENGINE")
if [[ $ENGINE == podman ]]; then
    missing=()
    for tool in podman runc; do command -v "$tool" >/dev/null || missing+=("$tool"); done
    [[ ${#missing[@]} -eq 0 ]] || apt_install "${missing[@]}"
    export CONTAINERS_CONF="${CONTAINERS_CONF:-$ROOT/docker/containers.conf}"
    ENG=(podman --runtime runc)
    [[ $BASE_IMAGE == */* ]] || BASE_IMAGE="docker.io/library/$BASE_IMAGE"  # no short names
fi
have() { "${ENG[@]}" image inspect "$1" >/dev/null 2>&1; }
if have "$BASE_IMAGE" || timeout 180 "${ENG[@]}" pull -q "$BASE_IMAGE" >/dev/null 2>&1; then
    log "base image $BASE_IMAGE"
elif have "$STANDIN"; then
    log "cannot pull $BASE_IMAGE: the stand-in $STANDIN is cached"
else
    log "cannot pull $BASE_IMAGE: making the stand-in $STANDIN (debootstrap, once)"
    command -v debootstrap >/dev/null || apt_install debootstrap
    rootfs="$(mktemp -d)"
    trap 'rm -rf "$rootfs" "$rootfs.log"' EXIT
    timeout 1200 debootstrap --variant=minbase \
        --include=python3,python3-venv,python3-pip,ca-certificates \
        bookworm "$rootfs" ${DEBIAN_MIRROR:+"$DEBIAN_MIRROR"} >"$rootfs.log" 2>&1 \
        || { tail -n 30 "$rootfs.log" >&2; die "debootstrap failed"; }
    # What the official slim image leaves out too: apt caches, docs, man pages, locales.
    rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/* \
        "$rootfs"/usr/share/{doc,man,info,locale}/*
    tar -C "$rootfs" -c . | timeout 600 "${ENG[@]}" import --change 'CMD ["/bin/bash"]' \
        --change 'ENV LANG=C.UTF-8' - "$STANDIN" >/dev/null || die "stand-in import failed"
fi
[[ ${1:-} == --bootstrap ]] && exit 0
export SMOKE_ENGINE="$ENGINE" SMOKE_REQUIRE=1  # from here a skip would hide a failure
exec "${PYTEST:-$ROOT/.venv/bin/pytest}" -p no:cacheprovider -m slow tests/deploy/test_container.py
