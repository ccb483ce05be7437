#!/usr/bin/env bash
# Retrain every shipped model from its recipe and regenerate the reports and README tables.
# Deterministic: the same code on the same machine writes the same weights.
# About 12 minutes on 2 cores (ghnet-temporal ~3, ghnet-epoch ~4, paper-s1 ~5). Then
# rebuild (the binaries embed the models) and run `cargo test -p ghnet-lab --test shipped`.
# SHARED points at the shared data folder (default ../shared, beside the repository).
set -euo pipefail
cd "$(dirname "$0")/.."
SHARED="${SHARED:-../shared}"
REAL="$SHARED/data/real/car-nagoya-2024-1hz.csv"
# The binary cargo builds, wherever CARGO_TARGET_DIR puts it.
G="${CARGO_TARGET_DIR:-target}/release/ghnet"
cargo build --release -p ghnet-lab --bin ghnet
# ghnet-temporal's recipe also tunes the Kalman filter baseline and writes kf.safetensors.
"$G" train --recipe ghnet-temporal --output models/inference/weights/ghnet-temporal.safetensors
for m in ghnet-epoch paper-s1; do
  "$G" train --recipe "$m" --output "models/inference/weights/$m.safetensors"
done
# The binary embeds the models: rebuild before evaluating the built-in names.
cargo build --release -p ghnet-lab --bin ghnet
for m in ghnet-epoch paper-s1; do
  "$G" eval --model "$m" --out-dir models/reports
done
"$G" eval --model ghnet-temporal > models/reports/ghnet-temporal.md
"$G" eval --model ghnet-temporal --data "$REAL" \
  --plot models/reports/car-nagoya-heading.svg > models/reports/car-nagoya.md
# The same against a kf tuned on that drive's own truth (the strongest kf there).
"$G" eval --model ghnet-temporal --data "$REAL" --kf tuned > models/reports/car-nagoya-kf-tuned.md
# Splice the tables into models/README.md between their markers.
python3 - <<'PY'
import re, pathlib
readme = pathlib.Path("models/README.md")
text = readme.read_text()
for name, file in (("ghnet-temporal", "ghnet-temporal.md"), ("car-nagoya", "car-nagoya.md")):
    table = pathlib.Path(f"models/reports/{file}").read_text().strip()
    text = re.sub(rf"(<!-- results:{name} -->\n).*?(\n<!-- /results:{name} -->)",
                  lambda m: m.group(1) + table + m.group(2), text, flags=re.S)
readme.write_text(text)
PY
bash models/unmet.sh
