"""Container health check: exit 0 when the service answers 200 on its readiness route.

Used by the image's HEALTHCHECK and by docker/compose.yaml. It needs nothing but the
standard library (the runtime image has no curl/wget). The port comes from POSE_PORT,
as for the service itself; the path can be overridden with POSE_HEALTH_PATH.
"""

from __future__ import annotations

import os
import sys
import urllib.error
import urllib.request

DEFAULT_PATH = "/v2/health/ready"


def main() -> int:
    port = os.environ.get("POSE_PORT", "8000")
    path = os.environ.get("POSE_HEALTH_PATH", DEFAULT_PATH)
    url = f"http://127.0.0.1:{port}{path}"
    # no proxy: a container given http_proxy (docker sets it from its client's config)
    # asked the proxy for its own loopback and was marked unhealthy (an ops audit)
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(url, timeout=3) as response:
            status = int(response.status)
    except urllib.error.HTTPError as exc:  # 503 while loading / warming up
        status = exc.code
    except (OSError, ValueError) as exc:
        print(f"unhealthy: {url}: {exc}", file=sys.stderr)
        return 1
    if status == 200:
        return 0
    print(f"unhealthy: {url}: HTTP {status}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
