#!/usr/bin/env bash
# Vendor three.js into service/static/vendor/three/ (the editor works offline: no CDN).
#
# Fetches the pinned release from the npm registry with `npm pack` (no node_modules, no
# install scripts) and copies the built ES module (three.module.js + three.core.js),
# OrbitControls and the licence. The page maps the bare specifier 'three' to the vendored
# module with an import map. Re-run after changing THREE_VERSION; commit the result.
set -euo pipefail
THREE_VERSION="${THREE_VERSION:-0.187.0}"
cd "$(dirname "$0")/.."
DEST=service/static/vendor/three
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT

(cd "$TMP" && npm pack --silent "three@${THREE_VERSION}" >/dev/null && tar -xzf "three-${THREE_VERSION}.tgz")
PKG="$TMP/package"
test "$(node -p "require('$PKG/package.json').version")" = "$THREE_VERSION"

rm -rf "$DEST"
mkdir -p "$DEST/addons/controls"
# Since r171 the module build is split (three.module.js imports ./three.core.js), and the
# npm package no longer ships minified builds: vendor both unminified files.
cp "$PKG/build/three.module.js" "$PKG/build/three.core.js" "$DEST/"
# The editor drags joints by ray-plane intersection, so only OrbitControls is needed.
cp "$PKG/examples/jsm/controls/OrbitControls.js" "$DEST/addons/controls/"
cp "$PKG/LICENSE" "$DEST/LICENSE"
{
  echo "three@${THREE_VERSION} from the npm registry (npm pack), vendored by scripts/vendor_three.sh"
  echo "sha512 of the tarball: $(cd "$TMP" && sha512sum "three-${THREE_VERSION}.tgz" | cut -d' ' -f1)"
  echo "files:"
  (cd "$DEST" && find . -type f ! -name VERSION | sort | sed 's/^/  /')
} > "$DEST/VERSION"
echo "vendored three@${THREE_VERSION} into $DEST"
