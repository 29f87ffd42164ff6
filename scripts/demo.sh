#!/usr/bin/env bash
# The main job, for now: render a small closet dataset with Drake and write its contact sheet.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${NFR_DEMO_OUT:-out/demo}
.venv/bin/nfr-drake generate --category closet --objects 6 --articulations 6 --views 4 --size 64 \
  --out "$out/closet_data"
.venv/bin/nfr-drake sheet --data "$out/closet_data" --out "$out/contact_sheet.png"
.venv/bin/nfr-drake captures --category closet --n 2 --out "$out/captures"
echo "demo: contact sheet at $out/contact_sheet.png, capture sets in $out/captures"
