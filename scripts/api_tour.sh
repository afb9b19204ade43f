#!/usr/bin/env bash
# Runs the README's API tour against a running server (default http://127.0.0.1:8000) and
# prints each command with its (abridged) answer. Usage: scripts/api_tour.sh [URL]
set -euo pipefail
URL=${1:-http://127.0.0.1:8000}
cd "$(dirname "$0")/.."
abridge() {  # keep two joints of any "pose" so answers fit on a page
  python3 -c '
import json, sys
def cut(o):
    if isinstance(o, dict):
        return {k: ({j: o[k][j] for j in list(o[k])[:2]} | {"...": "19 more joints"}
                    if k == "pose" and isinstance(o[k], dict) else cut(v)) for k, v in o.items()}
    if isinstance(o, list):
        return [cut(v) for v in o]
    return o
text = sys.stdin.read()
try:
    print(json.dumps(cut(json.loads(text)), indent=1))
except ValueError:
    print(text)
'
}
run() { echo "\$ $*"; eval "$@" | abridge; echo; }
run "curl -s $URL/v2/health/ready"
run "curl -s $URL/v1/solve -H 'content-type: application/json' -d @docs/examples/solve.json"
run "curl -s $URL/v1/complete -H 'content-type: application/json' -d @docs/examples/complete.json"
run "curl -s $URL/v1/solve/batch -H 'content-type: application/json' -d @docs/examples/batch.json"
run "curl -s $URL/v1/solve -H 'content-type: application/json' -d @docs/examples/bad.json"
echo "\$ curl -si $URL/v1/solve -H 'content-type: application/json' -d @docs/examples/solve.json | grep -i '^x-'"
curl -si "$URL/v1/solve" -H 'content-type: application/json' -d @docs/examples/solve.json | grep -i '^x-'
