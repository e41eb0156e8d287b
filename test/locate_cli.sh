#!/usr/bin/env bash
# cellsight_locate on real data, as a user would run it, with no settings file: the Stanford bunny
# (PLY clouds, model and scene), the same scene rewritten with double coordinates and scattered
# by 1 mm, the PCL milk carton (PCD), the UWA parasaurolophus mesh in millimetres; errors against
# the shipped truth where there is one; parts that are not in the scan; a memory limit that must
# refuse and one that must downsample; a corrupt file. Usage: locate_cli.sh <devel lib folder> <work folder>
set -uo pipefail
BIN=$1/cellsight_locate
WORK=$2
DATA=$(cd "$(dirname "$0")/../.." && pwd)/shared/data/pointclouds
if [ ! -f "$DATA/stanford_bunny/bun000.ply" ] || [ ! -f "$DATA/pcl/milk.pcd" ]; then
  echo "SKIP: real data not found under $DATA"
  exit 77
fi
rm -rf "$WORK" && mkdir -p "$WORK"
passed=0
failed=0
fail() { echo "FAIL: $*"; failed=$((failed + 1)); }
field() { /usr/bin/python3 -c 'import json,sys; v=json.load(open(sys.argv[1])).get(sys.argv[2]); print("" if v is None else v)' "$1" "$2"; }
within() { /usr/bin/python3 -c 'import sys; v=sys.argv[1]; sys.exit(0 if v and float(v) <= float(sys.argv[2]) else 1)' "$1" "$2"; }
check_found() {  # check_found <name> <max mm> <max deg> <args...>
  local name=$1 mm=$2 deg=$3
  shift 3
  "$BIN" "$@" --json "$WORK/$name.json" >"$WORK/$name.log" 2>&1
  local rc=$?
  if [ $rc -ne 0 ]; then fail "$name: exit $rc: $(tail -2 "$WORK/$name.log")"; return; fi
  if [ "$mm" != "-" ]; then
    local t r
    t=$(field "$WORK/$name.json" t_err_mm)
    r=$(field "$WORK/$name.json" r_err_deg)
    if within "$t" "$mm" && within "$r" "$deg"; then passed=$((passed + 1)); else fail "$name: error $t mm, $r deg"; return; fi
  else
    passed=$((passed + 1))
  fi
  echo "$name: $(head -2 "$WORK/$name.log" | tr '\n' ' ')"
}
B=$DATA/stanford_bunny
check_found bunny 2 1 --model "$B/bun045.ply" --scene "$B/bun000.ply" --model-sensor 0 0 1 --viewpoint 0 0 1 \
  --truth "$B/T_bun045_to_bun000.txt" --png "$WORK/bunny.png"
# the same scene with double coordinates (binary little-endian PLY)
/usr/bin/python3 - "$B/bun000.ply" "$WORK/bun000_double.ply" <<'PY'
import struct, sys
lines = open(sys.argv[1]).read().split("\n")
n = next(int(l.split()[2]) for l in lines if l.startswith("element vertex"))
body = lines[lines.index("end_header") + 1:]
pts = [tuple(map(float, l.split()[:3])) for l in body[:n]]
with open(sys.argv[2], "wb") as f:
    f.write(("ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty double x\nproperty double y\n"
             "property double z\nend_header\n" % len(pts)).encode())
    for p in pts:
        f.write(struct.pack("<3d", *p))
PY
check_found bunny_double 2 1 --model "$B/bun045.ply" --scene "$WORK/bun000_double.ply" --model-sensor 0 0 1 \
  --viewpoint 0 0 1 --truth "$B/T_bun045_to_bun000.txt"
# the same scene scattered by 1 mm (Gaussian, each axis): the RMSE limit follows the scan's scatter
/usr/bin/python3 - "$B/bun000.ply" "$WORK/bun000_noisy.ply" <<'PY'
import random, sys
lines = open(sys.argv[1]).read().split("\n")
n = next(int(l.split()[2]) for l in lines if l.startswith("element vertex"))
body = lines[lines.index("end_header") + 1:]
rnd = random.Random(7)
with open(sys.argv[2], "w") as f:
    f.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\nproperty float z\nend_header\n" % n)
    for l in body[:n]:
        f.write("%.6f %.6f %.6f\n" % tuple(float(c) + rnd.gauss(0, 0.001) for c in l.split()[:3]))
PY
check_found bunny_noisy 2 1 --model "$B/bun045.ply" --scene "$WORK/bun000_noisy.ply" --model-sensor 0 0 1 \
  --viewpoint 0 0 1 --truth "$B/T_bun045_to_bun000.txt"
printf '1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n' >"$WORK/identity.txt"
check_found milk 5 2 --model "$DATA/pcl/milk.pcd" --scene "$DATA/pcl/milk_cartoon_all_small_clorox.pcd" \
  --truth "$WORK/identity.txt"
if [ -f "$DATA/uwa/parasaurolophus_6700.ply" ]; then
  check_found uwa_rs1 - - --model "$DATA/uwa/parasaurolophus_6700.ply" --scene "$DATA/uwa/rs1_normals.ply" \
    --model-scale 0.001 --scene-scale 0.001 --png "$WORK/uwa_rs1.png"
fi
# memory: refused before reading, or downsampled with a warning
"$BIN" --model "$DATA/pcl/milk.pcd" --scene "$DATA/pcl/milk_cartoon_all_small_clorox.pcd" --memory-mb 1 >"$WORK/mem1.log" 2>&1
rc=$?
if [ $rc -eq 1 ] && grep -q "milk_cartoon_all_small_clorox.pcd: .* points need about .* MB, over --memory-mb 1" "$WORK/mem1.log"; then
  passed=$((passed + 1))
else
  fail "memory limit not refused (exit $rc): $(tail -1 "$WORK/mem1.log")"
fi
"$BIN" --model "$DATA/pcl/milk.pcd" --scene "$DATA/pcl/milk_cartoon_all_small_clorox.pcd" --memory-mb 60 \
  --truth "$WORK/identity.txt" --json "$WORK/mem60.json" >"$WORK/mem60.log" 2>&1
if grep -q "warning: .*downsampled to" "$WORK/mem60.log" && [ "$(field "$WORK/mem60.json" found)" = True ]; then
  passed=$((passed + 1))
else
  fail "downsampling to the memory limit: $(tail -2 "$WORK/mem60.log")"
fi
# a part that is not there: exit 3, and each refused pose names the test that refused it
"$BIN" --model "$B/bun045.ply" --scene "$DATA/pcl/milk_cartoon_all_small_clorox.pcd" --json "$WORK/absent.json" >"$WORK/absent.log" 2>&1
rc=$?
why=$(/usr/bin/python3 -c 'import json,sys; r=json.load(open(sys.argv[1])).get("rejected") or [{}]; print(r[0].get("refused_by", ""))' "$WORK/absent.json" 2>/dev/null)
if [ $rc -eq 3 ] && grep -q "the best poses refused, and why:" "$WORK/absent.log" && echo "$why" | grep -Eq '(> max_|< min_)[a-z_]+ '; then
  passed=$((passed + 1))
else
  fail "absent part (exit $rc, refused_by '$why'): $(tail -2 "$WORK/absent.log")"
fi
# the milk carton in the bunny scan: not there; its best pose leaves more than the scan's scatter allows
"$BIN" --model "$DATA/pcl/milk.pcd" --scene "$B/bun000.ply" --json "$WORK/absent_milk.json" >"$WORK/absent_milk.log" 2>&1
rc=$?
if [ $rc -eq 3 ] && grep -q "rmse .* mm > max_rmse" "$WORK/absent_milk.log"; then
  passed=$((passed + 1))
else
  fail "milk carton in the bunny scan (exit $rc): $(head -2 "$WORK/absent_milk.log")"
fi
# a corrupt scene: an error naming it, exit 1
head -c 300 "$DATA/pcl/milk.pcd" >"$WORK/broken.pcd"
"$BIN" --model "$DATA/pcl/milk.pcd" --scene "$WORK/broken.pcd" >"$WORK/broken.log" 2>&1
rc=$?
if [ $rc -eq 1 ] && grep -q "broken.pcd" "$WORK/broken.log"; then passed=$((passed + 1)); else fail "corrupt scene (exit $rc): $(tail -1 "$WORK/broken.log")"; fi
echo "$passed passed, $failed failed"
[ $failed -eq 0 ]
