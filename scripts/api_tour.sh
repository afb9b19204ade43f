#!/usr/bin/env bash
# Runs the README's API tour against a running server (default http://127.0.0.1:8000) and
# prints each command with its (abridged) answer. Usage: scripts/api_tour.sh [URL]
set -euo pipefail
URL=${1:-http://127.0.0.1:8000}
cd "$(dirname "$0")/.."
abridge() {  # keep two joints of a "pose", round to 0.1 mm, one line per vector
  python3 -c '
import json, re, sys
def cut(o):
    if isinstance(o, dict):
        out = {}
        for k, v in o.items():
            if k == "pose" and isinstance(v, dict):
                out[k] = {j: cut(v[j]) for j in list(v)[:2]}
                out[k]["..."] = f"{len(v) - 2} more joints"
            else:
                out[k] = cut(v)
        return out
    if isinstance(o, list):
        return [cut(v) for v in o]
    if isinstance(o, float):
        return float(f"{o:.4g}") if abs(o) < 1e-3 else round(o, 4)
    return o
text = sys.stdin.read()
try:
    pretty = json.dumps(cut(json.loads(text)), indent=1)
    print(re.sub(r"\[\s*([-\d.e]+),\s*([-\d.e]+),\s*([-\d.e]+)\s*\]", r"[\1, \2, \3]", pretty))
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
# characters: a BVH file edited in place (the edited frame's line shown), and a skeleton of
# the client's own answered in local rotations (three joints shown)
echo "\$ curl -s $URL/v1/bvh/solve -H 'content-type: application/json' -d @docs/examples/bvh_solve.json"
curl -s "$URL/v1/bvh/solve" -H 'content-type: application/json' -d @docs/examples/bvh_solve.json \
  | python3 -c 'import json, sys; a = json.load(sys.stdin); rows = a.pop("bvh").splitlines(); a["bvh"] = ["...", rows[-2][:60] + " ...", "..."]; a.pop("joint_map"); print(json.dumps(a, indent=1))' | abridge
echo
# a clip: three frames of the same file edited in one call (each edit's report abridged)
echo "\$ curl -s $URL/v1/bvh/solve/batch -H 'content-type: application/json' -d @docs/examples/bvh_solve_batch.json"
curl -s "$URL/v1/bvh/solve/batch" -H 'content-type: application/json' -d @docs/examples/bvh_solve_batch.json \
  | python3 -c '
import json, sys
a = json.load(sys.stdin)
rows, edits = a.pop("bvh").splitlines(), a.pop("edits")
a.pop("joint_map")
said = lambda rs: ", ".join("%s %.3g %s" % (r["joint"], r["error"], "reached" if r["reached"] else "short") for r in rs)
print("{\n \"edits\": [")
for e in edits:  # one line an edit: its frame, the joints rewritten, its targets and pins
    print("  {\"frame\": %d, \"changed_joints\": \"%d joints\", \"targets\": \"%s\", \"pins\": \"%s\"}," % (e["frame"], len(e["changed_joints"]), said(e["targets"]), said(e["pins"])))
print(" ],")
for k, v in a.items():
    print(" %s: %s," % (json.dumps(k), json.dumps(v)))
print(" \"bvh\": [\"...\", %s]\n}" % ", ".join(json.dumps(r[:40] + " ...") for r in rows[-3:]))
'
echo
echo "\$ curl -s $URL/v1/solve -H 'content-type: application/json' -d @docs/examples/solve_character.json"
curl -s "$URL/v1/solve" -H 'content-type: application/json' -d @docs/examples/solve_character.json \
  | python3 -c 'import json, sys; a = json.load(sys.stdin); a.pop("joint_map"); [a[k].__setitem__("...", f"{len(a[k]) - 3} more joints") or [a[k].pop(n) for n in list(a[k])[3:-1]] for k in ("rotations", "positions")]; print(json.dumps(a, indent=1))' | abridge
echo
echo "\$ curl -si $URL/v1/solve -H 'content-type: application/json' -d @docs/examples/solve.json | grep -i '^x-'"
curl -si "$URL/v1/solve" -H 'content-type: application/json' -d @docs/examples/solve.json | grep -i '^x-'
