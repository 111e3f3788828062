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
# A segmented organ for `augsim prepare`: the phantom's surface as a segmentation gives it, in mm
# in a scanner's frame (the phantom moved by (35, -60, -180) mm), with two holes, as ASCII STL
# (every vertex repeated); where it is held (4 points of the phantom's `fixed` region, between the
# lobes), the camera above it, and the demo's markers, cloud and truth in that frame.
"$augsim" mesh --tets 3000 -o phantom.stl >/dev/null
python3 - "$here" <<'PY'
import struct, sys
here, shift = sys.argv[1], (35.0, -60.0, -180.0)
data = open("phantom.stl", "rb").read()
count = struct.unpack_from("<I", data, 80)[0]
facets = [struct.unpack_from("<12f", data, 84 + 50 * k) for k in range(count)]
with open(f"{here}/organ.stl", "w") as f:
    f.write("solid organ\n")
    for k, v in enumerate(facets):
        if k in (100, 500):  # the holes
            continue
        f.write("facet normal %g %g %g\n outer loop\n" % v[:3])
        for i in range(3):
            f.write("  vertex %.4f %.4f %.4f\n" % tuple(1000.0 * v[3 + 3 * i + d] + shift[d] for d in range(3)))
        f.write(" endloop\nendfacet\n")
    f.write("endsolid organ\n")
def shifted(src, dst, unit, fmt):
    """The points of src moved into the scanner's frame; unit: metres per unit of the file."""
    rows = [[float(x) for x in l.split(",")] for l in open(src).read().split()[1:]]
    with open(dst, "w") as f:
        f.write("x,y,z\n")
        for r in rows:
            f.write(",".join(fmt % (r[d] + shift[d] * 1e-3 / unit) for d in range(3)) + "\n")
shifted(f"{here}/targets_mm.csv", f"{here}/organ_targets_mm.csv", 1e-3, "%.3f")
shifted(f"{here}/cloud.csv", f"{here}/organ_cloud.csv", 1.0, "%.5f")
shifted(f"{here}/truth.csv", f"{here}/organ_truth.csv", 1.0, "%.6f")
with open(f"{here}/organ_ligaments_mm.csv", "w") as f:
    f.write("x,y,z\n-8.25,-61.38,-202.25\n51.08,-61.38,-215.70\n23.33,-89.12,-207.89\n9.54,-31.71,-203.40\n")
PY
echo "wrote $here: cloud.csv, targets.csv, targets_mm.csv, truth.csv, tracks.csv, organ*"
