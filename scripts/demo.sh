#!/usr/bin/env bash
# The main job: simulated high-five (paper Sec. IV, Fig. 5-8) end to end, figures + report in ./interprim-demo
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh experiments
exec .venv/bin/interprim demo "$@"
