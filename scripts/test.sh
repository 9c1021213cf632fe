#!/usr/bin/env bash
# The test suite, from a fresh clone: venv + package with test extras (+ Debian's chromium for the
# browser test when running as root on Debian), then pytest.
#   bash scripts/test.sh          everything (what CI runs)
#   bash scripts/test.sh --fast   without the tests marked slow (subprocesses, builds, whole pipelines)
# Both first run the kernel-equivalence tests with NUMBA_DISABLE_JIT=1 (the kernels' bodies as Python).
# Other arguments go to pytest (and then only that pytest run happens).
set -euo pipefail
cd "$(dirname "$0")/.."
fast=0
args=()
for a in "$@"; do
  if [ "$a" = "--fast" ]; then fast=1; else args+=("$a"); fi
done
bash scripts/setup.sh test
if [ "$fast" = 0 ] && ! command -v chromium >/dev/null 2>&1 && [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null) \
    || echo "warning: could not install chromium; the browser test will be skipped" >&2
fi
export MPLBACKEND=Agg
if [ "${#args[@]}" = 0 ]; then
  # The compiled kernels' bodies run as Python (with NUMBA_DISABLE_JIT numba's njit returns the plain function)
  # against their numpy references, so the kernel code itself is covered; about half a minute.
  NUMBA_DISABLE_JIT=1 .venv/bin/python -m pytest -q tests/compiled/test_kernels_equivalence.py
fi
if [ "$fast" = 1 ]; then
  exec .venv/bin/python -m pytest -q -m "not slow" ${args[@]+"${args[@]}"}
fi
exec .venv/bin/python -m pytest -q ${args[@]+"${args[@]}"}
