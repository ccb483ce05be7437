# Sourced by the report scripts in this folder: from the repository root, builds the
# `ghnet` CLI and sets G (its path, wherever CARGO_TARGET_DIR puts it), T (a scratch
# folder removed on exit) and ROBOT (the simulator's turn-in-place robots: 0.3–2 m/s,
# spinning at 20–60 °/s at most stops).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
cargo build --release -p ghnet-lab --bin ghnet
G="${CARGO_TARGET_DIR:-target}/release/ghnet"
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
ROBOT="--platform-share 1 --platform-speed 0.3,2.0 --platform-spin 20,60 --platform-spin-share 0.9"
