#!/usr/bin/env bash
# Retrain both shipped models from their recipes and regenerate their reports.
# Deterministic: the same code on the same machine writes the same weights.
# About 5 minutes on 2 cores. Then rebuild (the binaries embed the models) and run
# `cargo test -p ghnet-lab --test shipped` to check the committed numbers.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p ghnet-lab --bin ghnet
for m in ghnet-full paper-s1; do
  ./target/release/ghnet train --recipe "$m" --output "models/inference/weights/$m.safetensors"
done
# The binary embeds the models: rebuild before evaluating the built-in names.
cargo build --release -p ghnet-lab --bin ghnet
for m in ghnet-full paper-s1; do
  ./target/release/ghnet eval --model "$m" --out-dir models/reports
done
# Splice the compact tables into models/README.md between their markers.
python3 - <<'PY'
import re, pathlib
readme = pathlib.Path("models/README.md")
text = readme.read_text()
for name in ("paper-s1", "ghnet-full"):
    table = pathlib.Path(f"models/reports/{name}.summary.md").read_text().strip()
    text = re.sub(rf"(<!-- results:{name} -->\n).*?(\n<!-- /results:{name} -->)",
                  lambda m: m.group(1) + table + m.group(2), text, flags=re.S)
readme.write_text(text)
PY
