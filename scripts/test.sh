#!/usr/bin/env bash
# The test suite, from a fresh clone: venv + package with test extras (+ Debian's chromium for the
# browser test when running as root on Debian), then pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh test
if ! command -v chromium >/dev/null 2>&1 && [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null) \
    || echo "warning: could not install chromium; the browser test will be skipped" >&2
fi
export MPLBACKEND=Agg
exec .venv/bin/python -m pytest -q "$@"
