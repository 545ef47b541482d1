#!/usr/bin/env bash
# One-time setup on a fresh machine (Python 3.11, Debian): everything the CLI and the tests need.
set -euo pipefail
cd "$(dirname "$0")"
PY=${PYTHON:-python3}
# CPU build of torch first: a bare "torch" requirement would pull a multi-GB CUDA build.
$PY -m pip install -q "torch==2.13.0"
$PY -m pip install -q -e ".[dev]"
# The Rerun viewer (rerun-sdk, for viz/) sends usage analytics unless told not to.
$PY -m rerun analytics disable >/dev/null 2>&1 || echo "setup: could not disable Rerun analytics" >&2
# PrusaSlicer slices the exported 3MF in the fabrication tests (skipped when it is missing).
if ! command -v prusa-slicer >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends prusa-slicer >/dev/null \
    || echo "setup: prusa-slicer could not be installed; slicer tests will skip" >&2
fi
echo "setup: done"
