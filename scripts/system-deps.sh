#!/usr/bin/env bash
# Installs the Debian packages the tests use, only those missing (idempotent).
# espeak-ng: the robots' speech (tests fall back to timed speech without it).
# postgresql: the server's second database; tests run a private cluster on 127.0.0.1.
# chromium, chromium-headless-shell: the browser tests (tests/web) drive the headless shell with
#   Playwright (a third less CPU); the benchmarks (bench/console.py) measure the browser.
# docker.io, debootstrap: tests/test_compose_engine.py runs docker-compose.yml on a private engine.
# redis-server: the broker between server processes; tests run a private one (tests/scale).
# nginx-light: tests/scale/test_proxy.py runs deploy/cluster/nginx.conf in front of two servers.
# mosquitto: the MQTT broker of VDA 5050 vehicles; tests run a private one (tests/vda5050).
# nodejs, npm: the OpenID Connect provider the single sign-on tests start (tests/oidc: node
#   oidc-provider, installed there with npm ci; it wants Node.js 20 or later).
# With arguments, only those packages (make demo: mosquitto).
set -euo pipefail
# One run at a time: `make test` runs this beside the TypeScript checker's set-up, which runs
# it for nodejs and npm, and apt refuses a second caller; a run that waited finds them there.
exec 9>"${TMPDIR:-/tmp}/guidebot-system-deps.lock"
command -v flock >/dev/null && flock 9
wanted=(espeak-ng postgresql chromium chromium-headless-shell docker.io debootstrap redis-server nginx-light prometheus mosquitto nodejs npm)
all=1
[ $# -gt 0 ] && wanted=("$@") && all=0
oidc="$(cd "$(dirname "$0")/.." && pwd)/tests/oidc"
oidc_provider() {
  if [ "$all" = 1 ] && [ ! -d "$oidc/node_modules/oidc-provider" ] && command -v npm >/dev/null; then
    echo "system-deps: installing the tests' OpenID provider (tests/oidc)"
    npm ci --prefix "$oidc" --no-audit --no-fund >/dev/null
  fi
}
trap oidc_provider EXIT
missing=()
for pkg in "${wanted[@]}"; do
  # Node.js from another source (NodeSource's nodejs carries npm and conflicts with Debian's
  # npm package) counts as there: the commands are what the tests need.
  case "$pkg" in nodejs) command -v node >/dev/null && continue ;; npm) command -v npm >/dev/null && continue ;; esac
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null; then
  echo "system-deps: no apt-get here; install ${missing[*]} by hand (the PostgreSQL tests need it)" >&2
  exit 0
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
echo "system-deps: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
