#!/usr/bin/env bash
# Set up somwidget on a fresh Debian machine (12 "bookworm" or later), as root or through sudo. Idempotent:
# a rerun skips what is already in place.
#   1. apt packages the app and its tests need (headless VTK rendering through EGL/Mesa, Chromium for the
#      browser tests, fonts); skipped when all are installed already
#   2. .venv at the repository root, with `pip install -e ".[test]"`; skipped while pyproject.toml is unchanged
#   3. the browser client's npm build (somwidget/frontend/client)
# Environment: PYTHON (default python3) picks the interpreter for the venv; SOMWIDGET_SKIP_APT=1 skips step 1.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT="$(pwd)"
PYTHON="${PYTHON:-python3}"
say() { printf '[setup] %s\n' "$*"; }

# -- 1. system packages --------------------------------------------------------------------------------------
# libegl1 libegl-mesa0 libgl1-mesa-dri: VTK's EGL render window on Mesa (llvmpipe) without a display;
# libosmesa6: VTK's OSMesa fallback window (it crashes when the library is missing); libglib2.0-0 libxrender1
# libx11-6: loaded by VTK and Chromium; chromium: the browser tests (Playwright drives /usr/bin/chromium).
PACKAGES=(chromium libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 libglib2.0-0 libxrender1 libx11-6
          fonts-dejavu-core ca-certificates)
if ! command -v "$PYTHON" >/dev/null 2>&1; then
    PACKAGES+=(python3 python3-venv python3-pip)
    PYTHON=python3
elif ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
    PACKAGES+=(python3-venv)  # Debian's python3 ships venv's ensurepip separately
fi
XR_DIR="somwidget/frontend/client"
if [ -f "$XR_DIR/package.json" ] && ! command -v npm >/dev/null 2>&1; then
    if command -v node >/dev/null 2>&1; then PACKAGES+=(npm); else PACKAGES+=(nodejs npm); fi
fi

installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q '^install ok installed$'; }
MISSING=()
for p in "${PACKAGES[@]}"; do installed "$p" || MISSING+=("$p"); done

if [ "${SOMWIDGET_SKIP_APT:-0}" = "1" ]; then
    say "apt: skipped (SOMWIDGET_SKIP_APT=1)${MISSING[*]:+; missing: ${MISSING[*]}}"
elif [ ${#MISSING[@]} -eq 0 ]; then
    say "apt: all ${#PACKAGES[@]} packages present, nothing to install"
else
    if ! command -v apt-get >/dev/null 2>&1; then
        say "apt: apt-get not found (not Debian?); install these by hand: ${MISSING[*]}" >&2
        exit 1
    fi
    SUDO=()
    if [ "$(id -u)" -ne 0 ]; then
        if command -v sudo >/dev/null 2>&1; then SUDO=(sudo); else
            say "apt: need root or sudo to install: ${MISSING[*]}" >&2
            exit 1
        fi
    fi
    say "apt: installing ${MISSING[*]}"
    "${SUDO[@]}" apt-get update
    "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y "${MISSING[@]}"
fi

# -- 2. Python environment -----------------------------------------------------------------------------------
VENV="$ROOT/.venv"
if [ ! -x "$VENV/bin/python" ]; then
    say "venv: creating $VENV with $("$PYTHON" --version 2>&1)"
    "$PYTHON" -m venv "$VENV"
else
    say "venv: $VENV exists ($("$VENV/bin/python" --version 2>&1))"
fi
STAMP="$VENV/.somwidget-install"
WANT="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT" ] && "$VENV/bin/python" -c 'import somwidget.cli' 2>/dev/null \
        && [ -x "$VENV/bin/somwidget" ]; then
    say "pip: somwidget[test] already installed for this pyproject.toml"
else
    say "pip: pip install -e \".[test]\""
    "$VENV/bin/python" -m pip install --upgrade pip
    "$VENV/bin/python" -m pip install -e ".[test]"
    echo "$WANT" >"$STAMP"
fi

# -- 3. WebXR client -----------------------------------------------------------------------------------------
if [ -f "$XR_DIR/package.json" ]; then
    LOCK_STAMP="$XR_DIR/node_modules/.somwidget-lock"
    LOCK_SUM="$(cat "$XR_DIR/package.json" "$XR_DIR/package-lock.json" 2>/dev/null | sha256sum | cut -d' ' -f1)"
    if [ -f "$LOCK_STAMP" ] && [ "$(cat "$LOCK_STAMP")" = "$LOCK_SUM" ]; then
        say "npm: $XR_DIR/node_modules up to date"
    else
        say "npm: npm ci in $XR_DIR"
        (cd "$XR_DIR" && npm ci --no-audit --no-fund)
        echo "$LOCK_SUM" >"$LOCK_STAMP"
    fi
    say "npm: npm run build in $XR_DIR"
    (cd "$XR_DIR" && npm run build)
else
    say "npm: no $XR_DIR/package.json, no WebXR build"
fi

say "done. Start the app: .venv/bin/somwidget serve   Tests: bash scripts/test.sh"
