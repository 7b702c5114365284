#!/usr/bin/env bash
# Regenerates every picture of the guide (docs/images/*.svg) from the commands shown beside
# it: runs the guide's pages (tests/docs.rs) and keeps the pictures they make.
set -euo pipefail
cd "$(dirname "$0")/.."
CROSSCAL_DOCS_UPDATE=1 cargo test --release --test main docs:: -- --test-threads=2
ls -l docs/images
