#!/usr/bin/env bash
# Set up nfr-drake on a fresh Debian/Ubuntu machine: system libraries, a virtualenv in .venv,
# the package with its dev extra. Idempotent: a second run only checks.
#   scripts/setup.sh          libraries for the library and the demo
#   scripts/setup.sh --tests  also what the tests need (headless Chromium for replay checks)
set -euo pipefail
cd "$(dirname "$0")/.."

want_tests=0
[[ "${1:-}" == "--tests" ]] && want_tests=1

as_root() { if [[ $(id -u) -eq 0 ]]; then "$@"; else sudo "$@"; fi; }
apt_updated=0
apt_install() {
  if [[ $apt_updated -eq 0 ]]; then as_root apt-get update -qq; apt_updated=1; fi
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

# open3d needs libusb at import time.
if ! ldconfig -p | grep -q 'libusb-1.0.so.0'; then
  echo "setup: installing libusb-1.0-0 (needed by open3d)"
  apt_install libusb-1.0-0
fi
if [[ $want_tests -eq 1 ]] && ! command -v chromium >/dev/null; then
  echo "setup: installing chromium (headless browser for the Meshcat replay tests)"
  apt_install chromium
fi

PYTHON=${PYTHON:-python3}
if [[ ! -x .venv/bin/python ]]; then
  echo "setup: creating .venv with $($PYTHON --version)"
  $PYTHON -m venv .venv
fi
stamp=.venv/.nfr-drake-installed
if [[ ! -f $stamp || pyproject.toml -nt $stamp ]]; then
  echo "setup: installing nfr-drake and its dependencies into .venv"
  .venv/bin/pip install -q --upgrade pip
  # torch first, pinned to the release this project is tested with (a CPU build where available).
  .venv/bin/pip install -q "torch==2.13.0"
  .venv/bin/pip install -q -e ".[dev]"
  touch "$stamp"
fi
echo "setup: ready (activate with: . .venv/bin/activate)"
