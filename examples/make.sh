#!/bin/sh
# Remakes every file of examples/ with augsim itself (examples/README.md says what each holds).
# augsim is taken from the PATH, or from $AUGSIM: AUGSIM=target/release/augsim examples/make.sh
set -eu
export LC_ALL=C
here=$(cd "$(dirname "$0")" && pwd)
augsim=${AUGSIM:-augsim}
case $augsim in */*) augsim=$(cd "$(dirname "$augsim")" && pwd)/$(basename "$augsim") ;; esac
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"

# CSV x,y,z rows scaled by $1 and printed with the format $2 (the header kept).
scaled() {
    awk -F, -v scale="$1" -v fmt="$2" \
        'NR == 1 { print; next } { printf fmt "," fmt "," fmt "\n", $1 * scale, $2 * scale, $3 * scale }' "$3"
}

# The built-in registration case of `augsim register --demo`: the liver phantom pushed down by 1.5 N
# (Neo-Hookean, about 9,000 T10) seen from above by a camera (1 mm noise, 5 % outliers), and its 10
# hidden markers. Run outside the repository, so the U-Net is skipped: only the case is kept.
"$augsim" register --demo --out demo >/dev/null
scaled 1 "%.5f" demo/case/cloud.csv >"$here/cloud.csv"
scaled 1 "%.6f" demo/case/targets_rest.csv >"$here/targets.csv"
scaled 1000 "%.3f" demo/case/targets_rest.csv >"$here/targets_mm.csv"
scaled 1 "%.6f" demo/case/truth.csv >"$here/truth.csv"

# Tracked surface points of the built-in ROUKF scenario roukf_young (synthetic, 40 steps).
"$augsim" assimilate roukf_young --iterations 40 -o young >/dev/null
awk -F, 'NR == 1 { print; next } { printf "%s,%s,%.6f,%.6f,%.6f\n", $1, $2, $3, $4, $5 }' \
    young/tracks/observations.csv >"$here/tracks.csv"
echo "wrote $here: cloud.csv, targets.csv, targets_mm.csv, truth.csv, tracks.csv"
