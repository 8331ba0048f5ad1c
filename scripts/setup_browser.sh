#!/usr/bin/env bash
# Install the headless browser of the HTML view's browser test (tests/test_view_browser.py):
# Debian's chromium and chromium-driver. Idempotent: when both are on PATH it only says so.
# Needs root (or sudo) for apt-get. Usage: scripts/setup_browser.sh   (or: make browser)
set -euo pipefail

log() { echo "[browser] $*"; }
if command -v chromium >/dev/null && command -v chromedriver >/dev/null; then
  log "chromium and chromedriver: installed ($(chromium --version 2>/dev/null | head -n1))"
  exit 0
fi
SUDO=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "[browser] ERROR: need root or sudo for apt-get" >&2; exit 1; }
  SUDO="sudo"
fi
log "installing chromium and chromium-driver with apt-get"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null
command -v chromium >/dev/null && command -v chromedriver >/dev/null \
  || { echo "[browser] ERROR: chromium or chromedriver missing after apt-get" >&2; exit 1; }
log "installed $(chromium --version 2>/dev/null | head -n1)"
