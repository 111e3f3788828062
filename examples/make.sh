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

# CSV x,y,z rows in metres, printed in millimetres with the format $1 under a header naming them.
in_mm() {
    awk -F, -v fmt="$1" \
        'NR == 1 { print "x_mm,y_mm,z_mm"; next } { printf fmt "," fmt "," fmt "\n", $1 * 1000, $2 * 1000, $3 * 1000 }' "$2"
}

# The built-in registration case of `augsim register --demo`: the liver phantom pushed down by 1.5 N
# (Neo-Hookean, about 9,000 T10) seen from above by a camera (1 mm noise, 5 % outliers), and its 10
# hidden markers. Only the case is kept, not the methods' registrations.
"$augsim" register --demo --out demo >/dev/null
in_mm "%.2f" demo/case/cloud.csv >"$here/cloud.csv"
in_mm "%.3f" demo/case/targets_rest.csv >"$here/targets.csv"
in_mm "%.3f" demo/case/truth.csv >"$here/truth.csv"

# Tracked surface points of the built-in ROUKF scenario roukf_young (synthetic, 40 steps).
"$augsim" assimilate roukf_young --iterations 40 -o young >/dev/null
awk -F, 'NR == 1 { print "frame,id,x_mm,y_mm,z_mm"; next } { printf "%s,%s,%.3f,%.3f,%.3f\n", $1, $2, $3 * 1000, $4 * 1000, $5 * 1000 }' \
    young/tracks/observations.csv >"$here/tracks.csv"
# A segmented organ for `augsim prepare`: the phantom's surface as a segmentation gives it, in mm
# in a scanner's frame (the phantom moved by (35, -60, -180) mm), with two holes, as ASCII STL
# (every vertex repeated); where it is held (4 points of the phantom's `fixed` region, between the
# lobes), the camera above it, and the demo's markers, cloud and truth in that frame, all in mm.
"$augsim" mesh --tets 3000 -o phantom.stl >/dev/null  # its boundary surface, in mm
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
            f.write("  vertex %.4f %.4f %.4f\n" % tuple(v[3 + 3 * i + d] + shift[d] for d in range(3)))
        f.write(" endloop\nendfacet\n")
    f.write("endsolid organ\n")
def shifted(name, fmt):
    """The points of name (mm) moved into the scanner's frame, as organ_name."""
    rows = [[float(x) for x in l.split(",")] for l in open(f"{here}/{name}").read().split()[1:]]
    with open(f"{here}/organ_{name}", "w") as f:
        f.write("x_mm,y_mm,z_mm\n")
        for r in rows:
            f.write(",".join(fmt % (r[d] + shift[d]) for d in range(3)) + "\n")
shifted("targets.csv", "%.3f")
shifted("cloud.csv", "%.2f")
shifted("truth.csv", "%.3f")
with open(f"{here}/organ_ligaments.csv", "w") as f:
    f.write("x_mm,y_mm,z_mm\n-8.25,-61.38,-202.25\n51.08,-61.38,-215.70\n23.33,-89.12,-207.89\n9.54,-31.71,-203.40\n")
PY
echo "wrote $here: cloud.csv, targets.csv, truth.csv, tracks.csv, organ*"
