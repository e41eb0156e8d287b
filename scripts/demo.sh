#!/usr/bin/env bash
# make demo: install what is missing, build, calibrate the simulated cell as a user would, run
# its cycle headless.
# Writes to <out>: captures/ (simulated calibration captures), calibration/ (what the
# calibration made: the pipeline reads only this), calibration_three_point/ (the thesis's method,
# beside it), images/ (captured frames), frames.json, truth/ (ground truth + true calibration,
# for the evaluation only), raw.bag (images, camera_info, tf, I/O), scan.ply, scanner.json,
# detections.json, error_budget.json, rviz.png, report.json, report.md, image_bytes.json, plans_raw.json
# (every grasp plan), assembly.json (assembly_client's steps), placements.json (placed vs target).
# Usage: scripts/demo.sh [build folder] [out folder]   (DEMO_LAUNCH_ARGS="nodelets:=false" adds launch args)
set -euo pipefail
BUILD=${1:-_build}
OUT=${2:-out/demo}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
export PATH=/usr/bin:/bin:/usr/sbin:/sbin:$PATH
now() { date +%s.%N; }

t0=$(now)
bash scripts/install-deps.sh
t1=$(now)
make --no-print-directory build BUILD="$BUILD" >/dev/null
t2=$(now)

source scripts/ros-env.sh "$BUILD"
source scripts/rviz-shot.sh
OUT=$(realpath -m "$OUT")
rm -rf "$OUT"
mkdir -p "$OUT"
LAUNCH_PID=""
cleanup() {
  [ -n "$LAUNCH_PID" ] && kill -INT "$LAUNCH_PID" 2>/dev/null && wait "$LAUNCH_PID" 2>/dev/null
  [ -n "${XVFB_PID:-}" ] && kill "$XVFB_PID" 2>/dev/null
  return 0
}
trap cleanup EXIT
SCENE=config/scenes/demo.yaml
TOOLS="$CELLSIGHT_BUILD/devel/lib/cellsight"
mkdir -p "$OUT/logs"
# run_step NAME CMD...: stdout to logs/NAME.json, stderr to logs/NAME.log; the demo stops with
# the cause when the step fails
run_step() {
  local name=$1
  shift
  if ! "$@" >"$OUT/logs/$name.json" 2>"$OUT/logs/$name.log"; then
    echo "demo: FAILED at '$name': $(grep -v '^\s*$' "$OUT/logs/$name.log" | tail -1)" >&2
    echo "demo: (command: $*; output in $OUT/logs/$name.log)" >&2
    exit 1
  fi
}
# 1. Calibration, as a user would do it, on captures of the simulated cell as built.
tc0=$(now)
run_step captures "$TOOLS/cellsight_simulate_captures" --scene "$SCENE" --out "$OUT/captures"
CAL="$OUT/calibration"
run_step calibration bash scripts/calibrate-captures.sh "$TOOLS" "$OUT/captures" "$CAL" "$OUT/calibration_three_point"
tc1=$(now)
echo "demo: calibrated the cell in $(/usr/bin/python3 -c "print(round($tc1 - $tc0, 1))") s: $CAL"

start_xvfb
echo "demo: simulated cell on $ROS_MASTER_URI, display $DISPLAY, output in $OUT"
t3=$(now)
roslaunch -p "${ROS_MASTER_URI##*:}" cellsight demo.launch out_dir:="$OUT" calibration_dir:="$CAL" rviz:=true assembly:=true \
  ${DEMO_LAUNCH_ARGS:-} \
  >"$OUT/launch.log" 2>&1 &
LAUNCH_PID=$!

# scan_client writes scan_result.json when the Scan action has finished.
deadline=$(( $(date +%s) + 600 ))
while [ ! -f "$OUT/scan_result.json" ]; do
  if ! kill -0 "$LAUNCH_PID" 2>/dev/null || grep -qE "(camera_trigger|scan_client|triangulation|cell_sim).*has died" "$OUT/launch.log"; then
    echo "demo: FAILED: the scan did not complete; see $OUT/launch.log" >&2
    grep -E "ERROR|FATAL|died" "$OUT/launch.log" | tail -5 >&2 || echo "demo: (no ERROR or FATAL line in launch.log)" >&2
    exit 1
  fi
  if [ "$(date +%s)" -gt "$deadline" ]; then
    echo "demo: FAILED: no scan result after 600 s; see $OUT/launch.log" >&2
    exit 1
  fi
  sleep 0.5
done
t4=$(now)
# wait_for FILE SECONDS NODES WHAT: wait until a node has written FILE; fail when one of NODES
# (a grep -E pattern) died or after SECONDS, with their last log lines
wait_for() {
  local file=$1 seconds=$2 nodes=$3 what=$4
  local deadline=$(( $(date +%s) + seconds ))
  while [ ! -f "$file" ]; do
    if [ "$(date +%s)" -gt "$deadline" ] || grep -qE "($nodes).*has died" "$OUT/launch.log"; then
      echo "demo: FAILED: $what within $seconds s; see $OUT/launch.log" >&2
      grep -E "$nodes" "$OUT/launch.log" | tail -5 >&2 || echo "demo: (no line of $nodes in launch.log)" >&2
      exit 1
    fi
    sleep 0.5
  done
}
# model_matching writes detections_raw.json once the scan's clusters are matched.
wait_for "$OUT/detections_raw.json" 180 "model_matching|clustering" "no detections after the scan"
# ... after the cycle's last pass (the file is rewritten after every pass)
deadline=$(( $(date +%s) + 180 ))
until /usr/bin/python3 -c 'import json,sys; sys.exit(0 if json.load(open(sys.argv[1])).get("final") else 1)' "$OUT/detections_raw.json" 2>/dev/null; do
  if [ "$(date +%s)" -gt "$deadline" ] || grep -qE "(model_matching|clustering).*has died" "$OUT/launch.log"; then
    echo "demo: FAILED: no detections of the cycle's last pass within 180 s; see $OUT/launch.log" >&2
    grep -E "model_matching" "$OUT/launch.log" | tail -5 >&2
    exit 1
  fi
  sleep 0.5
done
# the QR fixtures: qr_frame_adjustment writes its user frames with every fixture camera image (2 Hz)
wait_for "$OUT/fixtures_raw.json" 60 "qr_frame_adjustment" "qr_frame_adjustment wrote no fixtures"
# the simulated robot controller asks the bridge which fixture lies there and for the programs' user frames
BRIDGE_PORT=$(rosparam get /robot_bridge/bound_port 2>/dev/null || echo 0)
if ! "$TOOLS/cellsight_robot_client" --port "$BRIDGE_PORT" --json "$OUT/robot_session.json" \
    "HELLO demo_controller" ADJUST "UCS weld_a" "UCS glue_b" "UCS pick_c" QUIT >"$OUT/logs/robot_session.log" 2>&1; then
  echo "demo: FAILED: the simulated controller's session with robot_bridge: $(tail -1 "$OUT/logs/robot_session.log")" >&2
  exit 1
fi
# the assembly: assembly_client plans every part with grasp_planner and the simulated robot executes it
deadline=$(( $(date +%s) + 300 ))
until /usr/bin/python3 -c 'import json,sys; sys.exit(0 if json.load(open(sys.argv[1])).get("done") else 1)' "$OUT/assembly.json" 2>/dev/null; do
  if grep -qE "assembly_client.*(has died|has finished)|(grasp_planner|cell_sim).*has died" "$OUT/launch.log" || [ "$(date +%s)" -gt "$deadline" ]; then
    echo "demo: FAILED: the assembly did not complete; see $OUT/launch.log" >&2
    # the nodes' last lines, for the reader (sed: none found is not an error)
    sed -n -E '/assembly_client|grasp_planner/p' "$OUT/launch.log" | tail -5 >&2
    exit 1
  fi
  sleep 0.5
done
t_asm=$(now)
sleep 3  # let rviz draw the last frame
screenshot "$OUT/rviz.png"
# rviz must be alive and show the located parts and the scan; if not, it is started once more
# (its topics are latched) and the demo fails when that draws nothing either
rviz_problem() {
  if [ -n "${RVIZ_PID:-}" ]; then
    kill -0 "$RVIZ_PID" 2>/dev/null || { echo "rviz died (see $OUT/logs/rviz_retry.log)"; return; }
  elif grep -q "\[rviz-[0-9]*\] process has died" "$OUT/launch.log"; then
    echo "rviz died: $(grep "\[rviz-[0-9]*\] process has died" "$OUT/launch.log" | tail -1 | cut -c1-160)"
    return
  fi
  rviz_drawing_problem "$OUT/rviz.png"
}
problem=$(rviz_problem)
if [ -n "$problem" ]; then
  echo "demo: rviz: $problem; starting rviz again" >&2
  rosnode kill /rviz >/dev/null 2>&1
  rviz -d rviz/cell.rviz >"$OUT/logs/rviz_retry.log" 2>&1 &
  RVIZ_PID=$!
  sleep 20
  screenshot "$OUT/rviz.png"
  problem=$(rviz_problem)
  kill -INT "$RVIZ_PID" 2>/dev/null
  if [ -n "$problem" ]; then
    echo "demo: FAILED: rviz: $problem" >&2
    exit 1
  fi
fi
# What the 2 MP frames cost between processes (nodelets pass them by pointer inside the manager).
FRAMES=$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["cycle_frames"])' "$OUT/scan_result.json")
if /usr/bin/python3 scripts/topic-bytes.py /scanner_camera/image_raw --frames "$FRAMES" >"$OUT/image_bytes.json.tmp"; then
  mv "$OUT/image_bytes.json.tmp" "$OUT/image_bytes.json"
else
  rm -f "$OUT/image_bytes.json.tmp"
  echo "demo: warning: could not read the image topic's bus statistics" >&2
fi
kill -INT "$LAUNCH_PID"
launch_rc=0
wait "$LAUNCH_PID" || launch_rc=$?
LAUNCH_PID=""
# roslaunch exits 0 after an INT; anything else means a node or roslaunch itself failed
if [ "$launch_rc" -ne 0 ]; then
  echo "demo: FAILED: roslaunch exited with status $launch_rc on shutdown; see $OUT/launch.log" >&2
  exit 1
fi
t5=$(now)
if ! /usr/bin/python3 -c 'import json,sys; sys.exit(json.load(open(sys.argv[1]))["status"])' "$OUT/scan_result.json"; then
  echo "demo: FAILED: the scan was aborted: $(cat "$OUT/scan_result.json")" >&2
  exit 1
fi
# Scanner figures: the demo scan against the simulator's truth (+ K = 5 sphere sweeps with the
# same calibration and robot, MPE_AL).
run_step scanner_eval "$TOOLS/cellsight_scanner_accuracy" scan --scene "$SCENE" --cloud "$OUT/scan.ply" --k 5 \
  --calibration "$CAL" --json "$OUT/scanner_eval.json"
# Localisation figures: the detections against the simulator's truth.
# Exit 3 when a part is missed or a false one found: the report is still written, then the demo
# fails with that cause at its end.
eval_rc=0
"$TOOLS/cellsight_evaluate_localization" demo --scene "$SCENE" \
  --detections "$OUT/detections_raw.json" --json "$OUT/detections.json" || eval_rc=$?
# The error budget: the same recorded frames triangulated again in-process with the true
# calibration, then also with the true flange poses (no robot error left: image noise and the
# algorithms); the self-calibrated row is the live scan above, checked against an in-process rerun.
B="$OUT/budget"
mkdir -p "$B"
run_step budget_self "$TOOLS/cellsight_scanner_accuracy" frames --frames "$OUT/frames.json" --calibration "$CAL" \
  --scene "$SCENE" --ply "$B/scan_self_calibration.ply" --json "$B/scan_self_calibration.json"
run_step budget_true_cal "$TOOLS/cellsight_scanner_accuracy" frames --frames "$OUT/frames.json" \
  --calibration "$OUT/truth/calibration" --scene "$SCENE" --ply "$B/scan_true_calibration.ply" \
  --json "$B/scan_true_calibration.json"
run_step budget_true_all "$TOOLS/cellsight_scanner_accuracy" frames --frames "$OUT/frames.json" \
  --calibration "$OUT/truth/calibration" --flange-truth "$OUT/truth/frames_truth.jsonl" --scene "$SCENE" \
  --json "$B/scan_true_calibration_true_robot.json"
run_step budget_calibration "$TOOLS/cellsight_scanner_accuracy" calibration --calibration "$CAL" --scene "$SCENE" \
  --trajectories config/trajectories.yaml --trajectory "$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["trajectory"])' "$OUT/frames.json")" \
  --json "$B/calibration_error.json"
run_step budget_calibration_three_point bash -c "mkdir -p '$B/three_point' && cp '$CAL'/scanner_camera*.yaml '$B/three_point/' && \
  cp '$OUT/calibration_three_point/laser.yaml' '$B/three_point/' && \
  '$TOOLS/cellsight_scanner_accuracy' calibration --calibration '$B/three_point' --scene '$SCENE' --json '$B/calibration_error_three_point.json'"
# With the true calibration, exit 3 (a part missed or a false one) is a figure of the budget:
# detections.json's with_true_calibration reports tp/fp/fn. Any other failure stops the demo.
if "$TOOLS/cellsight_evaluate_localization" cloud --cloud "$B/scan_true_calibration.ply" --scene "$SCENE" \
  --json "$B/detections_true_calibration.json" >"$OUT/logs/budget_true_cal_locate.log" 2>&1; then
  true_loc_rc=0
else
  true_loc_rc=$?
fi
if [ "$true_loc_rc" -ne 0 ] && [ "$true_loc_rc" -ne 3 ]; then
  echo "demo: FAILED at 'budget_true_cal_locate': $(tail -1 "$OUT/logs/budget_true_cal_locate.log")" >&2
  exit 1
fi
# the user frames the node sent vs the truth, and the same chain over 100 noisy renders
run_step fixtures_compare "$TOOLS/cellsight_qr_fixtures" compare --fixtures "$OUT/fixtures_raw.json" --scene "$SCENE" \
  --registry config/fixtures.yaml --json "$OUT/fixtures.json"
run_step fixtures_sim "$TOOLS/cellsight_qr_fixtures" sim --scene "$SCENE" --registry config/fixtures.yaml \
  --calibration "$CAL" --renders 100 --json "$OUT/fixtures_renders.json"
# the assembly: where the simulator's truth says each part was put down, against its target
run_step placements "$TOOLS/cellsight_plan" demo --scene "$SCENE" --assembly "$OUT/assembly.json" \
  --truth "$OUT/truth/placements.jsonl" --json "$OUT/placements.json"
t6=$(now)

/usr/bin/python3 - "$OUT" "$t0" "$t1" "$t2" "$t3" "$t4" "$t5" "$t6" "$tc0" "$tc1" "$t_asm" <<'PY'
import json, os, sys, subprocess
import rosbag
out = sys.argv[1]
t0, t1, t2, t3, t4, t5, t6, tc0, tc1, t_asm = map(float, sys.argv[2:12])

def write_json(name, obj):
    tmp = os.path.join(out, name + ".tmp")
    with open(tmp, "w") as f:
        json.dump(obj, f, indent=2)
        f.write("\n")
    os.replace(tmp, os.path.join(out, name))

scan = json.load(open(os.path.join(out, "scan_result.json")))
ev = json.load(open(os.path.join(out, "scanner_eval.json")))
scanner = {
    "points": ev["points"],
    "frames": scan["frames"],
    "scan_seconds": round(scan["scan_seconds"], 3),
    "surface_error_rms_mm": ev["surface_error_rms_mm"],
    "surface_error_max_mm": ev["surface_error_max_mm"],
    "surface_error_p99_mm": ev["surface_error_p99_mm"],
    "mpe_p_mm": ev.get("mpe_p_mm"),
    "mpe_al_mm": ev.get("mpe_al_mm"),
    "notes": {
        "mpe_p_mm": "largest deviation from the least-squares sphere, reference sphere points of scan.ply",
        "mpe_al_mm": ev.get("mpe_al_method"),
        "surface_error": "distance of every scan.ply point to the nearest true surface of the scene",
    },
    "sphere_in_scan": ev.get("sphere_in_scan"),
}
B = os.path.join(out, "budget")
def jload(name):
    return json.load(open(os.path.join(B, name)))
self_rerun, true_cal, true_all = (jload("scan_self_calibration.json"), jload("scan_true_calibration.json"),
                                  jload("scan_true_calibration_true_robot.json"))
scan_fields = ("points", "surface_error_rms_mm", "surface_error_max_mm", "surface_error_p99_mm", "mpe_p_mm")
scanner["calibration"] = "self-calibrated: out/demo/calibration (simulated captures, cellsight_calibrate)"
scanner["with_true_calibration"] = {k: true_cal.get(k) for k in scan_fields}
scanner["with_true_calibration"]["note"] = "the same recorded frames triangulated in-process with truth/calibration"
write_json("scanner.json", scanner)
det_path = os.path.join(out, "detections.json")
loc_fields = ("tp", "fp", "fn", "precision", "recall", "f1", "median_t_err_mm", "median_r_err_deg")
det_true = jload("detections_true_calibration.json")
if os.path.exists(det_path):
    det = json.load(open(det_path))
    det["calibration"] = scanner["calibration"]
    det["with_true_calibration"] = {k: det_true.get(k) for k in loc_fields + ("parts",)}
    det["with_true_calibration"]["note"] = ("scan_true_calibration.ply clustered and located in-process "
                                            "(cellsight_evaluate_localization cloud)")
    write_json("detections.json", det)
cal_err = jload("calibration_error.json")
budget = {
    "scanner_surface_rms_mm": {
        "self_calibration_live": ev["surface_error_rms_mm"],
        "self_calibration_rerun": self_rerun["surface_error_rms_mm"],
        "true_calibration": true_cal["surface_error_rms_mm"],
        "true_calibration_true_robot": true_all["surface_error_rms_mm"],
    },
    "rows": {
        "image_and_algorithms": "true_calibration_true_robot: what is left with the truth everywhere",
        "robot": "true_calibration - true_calibration_true_robot: the robot's absolute error with an honest calibration",
        "calibration": "self_calibration - true_calibration: negative when calibrating with the same robot absorbs its "
                       "systematic error",
    },
    "calibration_error": cal_err,
    "calibration_error_three_point": jload("calibration_error_three_point.json"),
    "rerun_points": [self_rerun["points"], ev["points"]],
}
write_json("error_budget.json", budget)
frames = json.load(open(os.path.join(out, "frames.json")))
bag_path = os.path.join(out, "raw.bag")
topics = {}
with rosbag.Bag(bag_path) as bag:
    for topic, info in bag.get_type_and_topic_info().topics.items():
        topics[topic] = {"type": info.msg_type, "messages": info.message_count}
sd = subprocess.run(["/usr/bin/convert", os.path.join(out, "rviz.png"), "-colorspace", "Gray",
                     "-format", "%[fx:standard_deviation]", "info:"],
                    capture_output=True, text=True).stdout.strip()
report = {
    "what_ran": ["cellsight_simulate_captures", "cellsight_calibrate (intrinsics, extrinsics, laser lsq and three_point)",
                 "cell_sim", "calibration_publisher", "laser_plane_tracker", "triangulation", "clustering", "model_matching",
                 "camera_trigger (Scan action)", "scan_client", "grasp_planner", "robot_state_publisher", "assembly_client",
                 "rosbag record", "rviz (Xvfb)",
                 "cellsight_scanner_accuracy scan"],
    "scene": "config/scenes/demo.yaml",
    "trajectory": frames["trajectory"],
    "frames_planned": frames["poses"],
    "frames": len(frames["frames"]),
    "scan_seconds": round(frames["scan_seconds"], 3),
    "seconds": {
        "install_deps": round(t1 - t0, 2),
        "calibration": round(tc1 - tc0, 2),
        "build": round(t2 - t1, 2),
        "launch_to_scan_done": round(t4 - t3, 2),
        "shutdown_and_screenshot": round(t5 - t4, 2),
        "scanner_evaluation": round(t6 - t5, 2),
        "total": round(t6 - t0, 2),
    },
    "bag": {"path": "raw.bag", "bytes": os.path.getsize(bag_path), "topics": topics},
    "rviz_png_grey_stddev": float(sd) if sd else None,
    "outputs": sorted(os.listdir(out)),
}
report["scanner"] = scanner
import re
clusters = re.findall(r"clustering: (\d+) points -> (\d+) clusters", open(os.path.join(out, "launch.log")).read())
if clusters:
    report["clustering"] = {"input_points": int(clusters[0][0]), "clusters": int(clusters[0][1]),
                            "objects_in_scene": len(json.load(open(os.path.join(out, "truth", "scene_truth.json")))["objects"])}
if os.path.exists(det_path):
    det = json.load(open(det_path))
    report["localization"] = {k: det[k] for k in ("tp", "fp", "fn", "median_t_err_mm", "median_r_err_deg", "locate_seconds")}
pl = json.load(open(os.path.join(out, "placements.json")))
report["placements"] = [{k: p.get(k) for k in ("object", "model", "status", "reason", "place_t_err_mm", "place_r_err_deg",
                                               "plan_seconds", "motion_seconds", "truth")} for p in pl["placements"]]
plan_s = sum(p["plan_seconds"] for p in pl["placements"])
exec_s = sum(p.get("motion_seconds") or 0.0 for p in pl["placements"])
report["cycle_seconds"] = {
    "calibration": round(tc1 - tc0, 2),
    "scan": round(scan.get("cycle_scan_seconds", scan["scan_seconds"]), 2),
    "locate": round(report.get("localization", {}).get("locate_seconds", 0.0), 3),
    "plan": round(plan_s, 3),
    "execute": round(exec_s, 2),
    "assembly_wall": round(t_asm - t4, 2),
    "note": "scan: the Scan action, every pass; locate: model_matching, the last pass; plan: grasp_planner per part, summed; execute: the simulated "
            "robot's motion (assembly_time_scale x faster than planned); assembly_wall: scan done to assembly done",
}
ib_path = os.path.join(out, "image_bytes.json")
if os.path.exists(ib_path):
    ib = json.load(open(ib_path))
    report["image_transport"] = {"bytes_sent_per_frame": ib.get("bytes_sent_per_frame"),
                                 "subscribers": ib.get("subscribers"),
                                 "publishers": ib.get("publishers")}
report["scan_passes"] = {"cycle_id": scan.get("cycle_id", ""),
                         "passes": [{k: p.get(k) for k in ("trajectory", "role", "frames", "points", "scan_seconds")}
                                    for p in scan.get("passes", [])],
                         "note": "the cycle's scan passes (role 0 detect, 1 add_detections, 2 refine); the scanner "
                                 "figures are the first pass's"}
write_json("report.json", report)
# the readable report
lines = ["# cellsight demo cell cycle", "",
         "Simulated cell `%s`, self-calibrated (`calibration/`), scanned in %d passes (%s; %d frames in the first), located, "
         "planned and assembled by the simulated robot. Figures against the simulator's truth." % (
             report["scene"], max(1, len(report["scan_passes"]["passes"])),
             ", ".join(p["trajectory"] for p in report["scan_passes"]["passes"]) or report["trajectory"], report["frames"]),
         "", "![rviz: the robot, the OctoMap of the scan, the last path](rviz.png)", "",
         "## Cycle", "", "| stage | seconds |", "|---|---|"]
for k in ("calibration", "scan", "locate", "plan", "execute", "assembly_wall"):
    lines.append("| %s | %s |" % (k, report["cycle_seconds"][k]))
lines += ["", "## Scanner", "", "surface error RMS %.4f mm, max %.4f mm over %d points" % (
    scanner["surface_error_rms_mm"], scanner["surface_error_max_mm"], scanner["points"])]
if "localization" in report:
    loc = report["localization"]
    lines += ["", "## Localisation", "", "%d found, %d missed, %d false; median %.3f mm, %.3f deg from the truth" % (
        loc["tp"], loc["fn"], loc["fp"], loc["median_t_err_mm"], loc["median_r_err_deg"])]
lines += ["", "## Placements", "", "| part | status | placed vs target | plan | motion |", "|---|---|---|---|---|"]
for p in report["placements"]:
    err = ("%.3f mm, %.3f deg" % (p["place_t_err_mm"], p["place_r_err_deg"])) if p.get("place_t_err_mm") is not None else p.get("reason", "")
    lines.append("| %s (%s) | %s | %s | %.0f ms | %s |" % (p["object"], p["model"], p["status"], err, p["plan_seconds"] * 1e3,
                                                       ("%.1f s" % p["motion_seconds"]) if p.get("motion_seconds") else "-"))
with open(os.path.join(out, "report.md.tmp"), "w") as f:
    f.write("\n".join(lines) + "\n")
os.replace(os.path.join(out, "report.md.tmp"), os.path.join(out, "report.md"))
print(json.dumps({k: report[k] for k in ("frames", "frames_planned", "scan_seconds", "seconds", "clustering", "localization",
                                         "cycle_seconds", "placements") if k in report}, indent=1))
print(json.dumps({k: v for k, v in scanner.items() if k not in ("notes", "sphere_in_scan")}, indent=1))
print(json.dumps({"error_budget_surface_rms_mm": budget["scanner_surface_rms_mm"]}, indent=1))
missing = [t for t in ("/scanner_camera/image_raw", "/scanner_camera/camera_info", "/tf", "/tf_static") if t not in topics]
if len(frames["frames"]) != frames["poses"] or missing:
    print("demo: FAILED: frames %d/%d, topics missing from the bag: %s" % (len(frames["frames"]), frames["poses"], missing))
    sys.exit(1)
PY
if [ "$eval_rc" -ne 0 ]; then
  echo "demo: FAILED: the localisation evaluation exited with $eval_rc (3: a part missed or a false detection); see $OUT/detections.json" >&2
  exit 1
fi
/usr/bin/python3 -c '
import json, sys
for f in json.load(open(sys.argv[1])):
    print("demo: fixture %s -> %s: UCS %s" % (f["type"], f["program"], f["status"] if f["status"] != "ok" else
          "%.3f mm / %.3f deg from the truth (free 6-DoF: %.3f mm / %.3f deg)" %
          (f["t_err_mm"], f["r_err_deg"], f["free_t_err_mm"], f["free_r_err_deg"])))
' "$OUT/fixtures.json"
echo "demo: done: $OUT"
