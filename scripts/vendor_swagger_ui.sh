#!/usr/bin/env bash
# Vendor Swagger UI into service/vendor/swagger-ui/ (/docs works offline: no CDN).
#
# Fetches the pinned swagger-ui-dist release from the npm registry with `npm pack` (no
# install scripts) and copies the bundle, its stylesheet and the licences. The service's
# /docs page loads them from /docs/assets with its own init script (no inline script, so
# the page's Content-Security-Policy allows 'self' only). Re-run after changing the
# version; commit the result.
set -euo pipefail
SWAGGER_UI_VERSION="${SWAGGER_UI_VERSION:-5.32.2}"
cd "$(dirname "$0")/.."
DEST=service/vendor/swagger-ui
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT

(cd "$TMP" && npm pack --silent "swagger-ui-dist@${SWAGGER_UI_VERSION}" >/dev/null \
  && tar -xzf "swagger-ui-dist-${SWAGGER_UI_VERSION}.tgz")
PKG="$TMP/package"
test "$(node -p "require('$PKG/package.json').version")" = "$SWAGGER_UI_VERSION"
mkdir -p "$DEST"
rm -f "$DEST"/swagger-ui-bundle.js "$DEST"/swagger-ui.css
cp "$PKG"/{swagger-ui-bundle.js,swagger-ui.css,LICENSE,NOTICE,swagger-ui-bundle.js.LICENSE.txt} "$DEST/"
{
  echo "swagger-ui-dist@${SWAGGER_UI_VERSION} from the npm registry (npm pack), vendored by scripts/vendor_swagger_ui.sh"
  echo "sha512 of the tarball: $(cd "$TMP" && sha512sum "swagger-ui-dist-${SWAGGER_UI_VERSION}.tgz" | cut -d' ' -f1)"
} > "$DEST/VERSION"
echo "vendored swagger-ui-dist ${SWAGGER_UI_VERSION} into ${DEST}"
