"""The memory the service's image keeps across bursts of the heaviest admitted loads, in a
container run as the container check runs it (docs/deploy.md, "Measured figures": "The
same image run as the check runs it …").

podman (``--runtime runc``, ``docker/containers.conf``, as ``tests/deploy/test_container.py``)
runs IMAGE with the check's flags (``--read-only --tmpfs /tmp --cap-drop ALL
--security-opt no-new-privileges``) on 127.0.0.1:18750-18799; a burst is the check's own
(``heavy_loads()``: 64 item lists of 1,024 exact-reach items, 42 columnar batches, 8 BVH
solves and 8 inspects of 7.6 MB, each kind's requests at once), ``--bursts`` of them one
after the other. ``/proc/1/status`` (the service is PID 1) is read with ``podman exec``
once ready and ``--after`` seconds after each burst (VmRSS), VmHWM at the end; one line
to paste, then one JSON line. The loopback form, without a container, is
``scripts/rss_bursts.py``.

    PYTHONPATH=. python scripts/figures/container_bursts.py localhost/marionette:smoke
    PYTHONPATH=. python scripts/figures/container_bursts.py IMAGE --bursts 4 --after 5 30 60
    PYTHONPATH=. python scripts/figures/container_bursts.py IMAGE --unsetenv MALLOC_ARENA_MAX
"""

from __future__ import annotations

import argparse
import json
import os
import threading
import time
from collections import Counter

import httpx
from loopback import ROOT, port

from tests.deploy.test_container import SECURITY, Engine, heavy_loads, remove, vm


def podman() -> Engine:
    env = {**os.environ, "CONTAINERS_CONF": str(ROOT / "docker" / "containers.conf")}
    return Engine("podman", ["podman", "--runtime", "runc"], env)


def burst(client: httpx.Client, loads: list[tuple[str, bytes, int]], codes: Counter[int]) -> None:
    for path, body, n in loads:

        def one(path: str = path, body: bytes = body) -> None:
            head = {"content-type": "application/json"}
            codes[client.post(path, content=body, headers=head, timeout=120).status_code] += 1

        threads = [threading.Thread(target=one) for _ in range(n)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("image")
    parser.add_argument("--bursts", type=int, default=10)
    parser.add_argument("--after", type=float, nargs="+", default=[60.0], help="seconds")
    parser.add_argument(
        "--unsetenv",
        action="append",
        default=[],
        metavar="NAME",
        help="unset the image's NAME (MALLOC_ARENA_MAX: glibc's default arenas)",
    )
    args = parser.parse_args()
    engine, name, p = podman(), f"marionette-figures-{os.getpid()}", port()
    flags = [*SECURITY, "-p", f"127.0.0.1:{p}:8000", "--health-interval", "disable"]
    flags += [f"--unsetenv={name}" for name in args.unsetenv]
    loads = heavy_loads()
    out: dict[str, object] = {"image": engine.inspect("image", args.image, "{{.Id}}")[:12]}
    out["unset"] = args.unsetenv
    codes: Counter[int] = Counter()
    after: list[list[int]] = []
    engine.run("run", "-d", "--name", name, *flags, args.image)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{p}") as client:
            limit = time.monotonic() + 240
            while True:
                try:
                    if client.get("/v2/health/ready", timeout=3).status_code == 200:
                        break
                except httpx.HTTPError:
                    pass
                if time.monotonic() > limit:
                    raise SystemExit("the container did not become ready")
                time.sleep(0.25)
            time.sleep(1)
            out["rss_mib_ready"] = round(vm(engine, name, "VmRSS"))
            for _ in range(args.bursts):
                burst(client, loads, codes)
                ended, reads = time.monotonic(), []
                for at in args.after:
                    time.sleep(max(0.0, ended + at - time.monotonic()))
                    reads.append(round(vm(engine, name, "VmRSS")))
                after.append(reads)
            out["rss_mib_peak"] = round(vm(engine, name, "VmHWM"))
    finally:
        remove(engine, name)
    out["rss_mib_after_each_burst"] = after
    out["codes"] = dict(sorted(codes.items()))
    last = ", ".join("/".join(map(str, reads)) for reads in after)
    print(
        f"{args.image} ({out['image']}{''.join(f', {n} unset' for n in args.unsetenv)}): "
        f"{out['rss_mib_ready']} MiB once ready; after the "
        f"bursts ({'/'.join(f'{a:g}' for a in args.after)} s) {last} MiB; VmHWM "
        f"{out.get('rss_mib_peak')} MiB"
    )
    print(json.dumps(out))


if __name__ == "__main__":
    main()
