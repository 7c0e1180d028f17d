#!/usr/bin/env bash
# Copies the pinned front-end libraries (package.json + package-lock.json) into web/vendor/ with
# their licence files. Run it after changing a version; commit web/vendor/. Needs npm; running
# GuideBot does not (the pages import web/vendor/ through each page's import map). Pin the same
# versions in tools/typecheck/package.json: the type check reads their types there (a test says so).
set -euo pipefail
cd "$(dirname "$0")/.."
npm ci --no-audit --no-fund --ignore-scripts
out=web/vendor
rm -rf "$out"
mkdir -p "$out/leaflet" "$out/lit-html/directives" "$out/axe-core" "$out/swagger-ui" "$out/uplot"

# Leaflet: the ES module build, its stylesheet and marker images.
cp node_modules/leaflet/dist/leaflet-src.esm.js node_modules/leaflet/dist/leaflet.css \
  node_modules/leaflet/LICENSE "$out/leaflet/"
cp -r node_modules/leaflet/dist/images "$out/leaflet/images"

# lit-html: the production modules only (no source maps, typings or the development build).
for f in node_modules/lit-html/*.js; do cp "$f" "$out/lit-html/"; done
for f in node_modules/lit-html/directives/*.js; do cp "$f" "$out/lit-html/directives/"; done
cp node_modules/lit-html/LICENSE "$out/lit-html/"

# axe-core: accessibility checks, loaded by the browser tests only.
cp node_modules/axe-core/axe.min.js node_modules/axe-core/LICENSE \
  node_modules/axe-core/LICENSE-3RD-PARTY.txt "$out/axe-core/"

# Swagger UI: the API docs page /docs (web/api-docs/), served from here, not from a CDN.
cp node_modules/swagger-ui-dist/swagger-ui-bundle.js \
  node_modules/swagger-ui-dist/swagger-ui-bundle.js.LICENSE.txt \
  node_modules/swagger-ui-dist/swagger-ui.css node_modules/swagger-ui-dist/favicon-32x32.png \
  node_modules/swagger-ui-dist/LICENSE node_modules/swagger-ui-dist/NOTICE "$out/swagger-ui/"

# uPlot: the staff console's report charts (web/admin/views/reports.js), its ES module build.
cp node_modules/uplot/dist/uPlot.esm.js node_modules/uplot/dist/uPlot.min.css \
  node_modules/uplot/LICENSE "$out/uplot/"

# Source maps are not vendored: drop the comments that point at them.
find "$out" -name '*.js' -exec sed -i '/^\/\/# sourceMappingURL=/d' {} +
node -e 'const l=require("./package-lock.json").packages;for(const[k,v]of Object.entries(l))if(k)console.log(k.replace("node_modules/",""),v.version,v.license)' \
  > "$out/VERSIONS.txt"
echo "vendor-web: copied $(grep -c . "$out/VERSIONS.txt") packages into $out"
