#!/usr/bin/env bash
# Build the documentation site (guides + API reference) with MkDocs, strict (any warning fails):
#   bash scripts/docs.sh [DIR]      -> DIR/index.html (default ./site, git-ignored)
# Installs the [docs] extra into .venv first. Nothing is fetched at build time; the pages load MathJax
# from a CDN when viewed. Live preview while editing: .venv/bin/mkdocs serve
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh docs
export NO_MKDOCS_2_WARNING=1
exec .venv/bin/mkdocs build --strict --site-dir "${1:-site}"
