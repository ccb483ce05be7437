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

# The row whose label is $1 (`**all**`, `after first motion`) of the first table of a
# `ghnet eval` output on stdin: MAE of atan2, kf and the model, and the model's shares
# within 1σ and 2σ, its columns found by the table's header (a receiver-course column
# comes and goes).
eval_row() {
  awk -F'|' -v row="$1" '
    /MAE atan2/ && !a { for (i = 1; i <= NF; i++) {
        if ($i ~ /MAE atan2/) a = i; else if ($i ~ /MAE kf/) k = i;
        else if ($i ~ /MAE / && $i !~ /receiver/) m = i;
        else if ($i ~ /≤1σ/) s1 = i; else if ($i ~ /≤2σ/) s2 = i } }
    a && index($2, row) && !done { print $a + 0, $k + 0, $m + 0, $s1 + 0, $s2 + 0; done = 1 }'
}
