#!/usr/bin/env python3
"""Soak driver: runs the cell cycle (Scan action -> scan/cloud -> clusters -> detections, then the
locate_objects service) N times against one set of running nodes, and after every cycle samples
each node's resident memory and open files (/proc of the PID its XML-RPC API gives).

Writes <out>/soak.csv (one row per cycle and process) and <out>/soak.json (per process: the RSS
trend in kB per cycle after the warm-up -- Theil-Sen, the median of pairwise slopes, so that a
step of the allocator or noise does not read as a leak -- beside the least-squares slope; open-file
growth; cycle times: median, max, max / median; failures). Exit 1 when a cycle failed, a trend is
over --max-slope-kb, open files grew by more than --max-fd-growth, or (with --max-cycle-ratio) a
cycle took longer than that many medians.

Usage: soak_driver.py --cycles 50 --trajectory quick_sweep --out out/soak [--warmup N]
"""
import argparse
import json
import logging
import os
import statistics
import sys
import time
import xmlrpc.client

import actionlib
import rosgraph
import rospy
from cellsight.msg import DetectionArray, ScanAction, ScanGoal
from cellsight.srv import LocateObjects

NODES = ["cell_sim", "image_manager", "camera_trigger", "laser_plane_tracker", "triangulation",
         "clustering", "model_matching", "calibration_publisher", "scanner_calibration"]


def pid_of(master, node):
    """The process id of /node (None when it is not registered or does not answer)."""
    try:
        uri = master.lookupNode("/" + node)
        code, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/soak_driver")
        return pid if code == 1 else None
    except Exception:  # not running (e.g. a node that runs as a nodelet)
        return None


def sample(pid):
    """(RSS in kB, open files) of a process, (None, None) when it is gone."""
    try:
        rss = None
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    rss = int(line.split()[1])
        return rss, len(os.listdir("/proc/%d/fd" % pid))
    except OSError:
        return None, None


def slope(xs, ys):
    """Least-squares slope of ys over xs (0 for fewer than two points)."""
    if len(xs) < 2:
        return 0.0
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx if sxx > 0 else 0.0


def theil_sen(xs, ys):
    """Median of the pairwise slopes: a steady growth shows in it, a single step or noise hardly."""
    pairs = [(ys[j] - ys[i]) / (xs[j] - xs[i]) for i in range(len(xs)) for j in range(i + 1, len(xs)) if xs[j] != xs[i]]
    return statistics.median(pairs) if pairs else 0.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=50)
    ap.add_argument("--trajectory", default="quick_sweep")
    ap.add_argument("--out", required=True)
    ap.add_argument("--warmup", type=int, default=-1,
                    help="cycles left out of the slope while pools and caches fill; default 20 or a tenth of the cycles, whichever is more")
    ap.add_argument("--cycle-timeout", type=float, default=300.0)
    ap.add_argument("--max-slope-kb", type=float, default=8.0, help="RSS trend limit per process, kB per cycle")
    ap.add_argument("--max-fd-growth", type=int, default=4, help="open files a process may gain over the run")
    ap.add_argument("--max-cycle-ratio", type=float, default=0.0, help="fail when a cycle exceeds this many medians (0: report only)")
    a = ap.parse_args(rospy.myargv()[1:])
    if a.warmup < 0:
        a.warmup = min(max(20, a.cycles // 10), a.cycles - 3)
    if a.cycles < 3 or a.warmup >= a.cycles - 1:
        ap.error("--cycles must be >= 3 and --warmup below cycles - 1")
    os.makedirs(a.out, exist_ok=True)

    rospy.init_node("soak_driver", disable_signals=True)
    # actionlib's Python SimpleActionClient logs an error for each status update of the previous
    # (finished) goal that arrives after the next goal was sent; it is not a failure of the cycle
    logging.getLogger("rosout").addFilter(lambda r: "goal handle that we're not tracking" not in r.getMessage())
    master = rosgraph.Master("/soak_driver")
    scan = actionlib.SimpleActionClient("scan", ScanAction)
    if not scan.wait_for_server(rospy.Duration(120)):
        sys.exit("soak: no Scan action server within 120 s: is the cell running?")
    rospy.wait_for_service("model_matching/locate_objects", 120)
    locate = rospy.ServiceProxy("model_matching/locate_objects", LocateObjects)
    detections = {"count": 0}

    def on_detections(_msg):
        detections["count"] += 1

    rospy.Subscriber("detections", DetectionArray, on_detections)
    pids = {n: p for n in NODES for p in [pid_of(master, n)] if p}
    if not pids:
        sys.exit("soak: no node of the cell answered getPid")

    rows, times, failures = [], [], []
    for cycle in range(a.cycles):
        t0 = time.monotonic()
        seen = detections["count"]
        ok, why = True, ""
        scan.send_goal(ScanGoal(trajectory=a.trajectory))
        if not scan.wait_for_result(rospy.Duration(a.cycle_timeout)):
            scan.cancel_goal()
            ok, why = False, "scan timed out"
        elif scan.get_result().status != 0:
            ok, why = False, "scan failed: " + scan.get_result().message
        else:  # the clusters of this scan reach model_matching, which publishes its detections
            end = time.monotonic() + a.cycle_timeout
            while detections["count"] == seen and time.monotonic() < end:
                time.sleep(0.02)
            if detections["count"] == seen:
                ok, why = False, "no detections after the scan"
            else:
                try:
                    r = locate()
                    if r.status != 0:
                        ok, why = False, "locate_objects: " + r.message
                except rospy.ServiceException as e:
                    ok, why = False, "locate_objects: %s" % e
        dt = time.monotonic() - t0
        times.append(dt)
        if not ok:
            failures.append({"cycle": cycle, "why": why})
            print("soak: cycle %d FAILED: %s" % (cycle, why), flush=True)
        for node, pid in pids.items():
            rss, fds = sample(pid)
            rows.append((cycle, node, pid, rss, fds, dt, int(ok)))
            if rss is None:
                failures.append({"cycle": cycle, "why": "%s (pid %d) is gone" % (node, pid)})
        if cycle % 10 == 0 or cycle == a.cycles - 1:
            print("soak: cycle %d/%d %.2f s %s" % (cycle + 1, a.cycles, dt, "ok" if ok else "FAILED"), flush=True)
        if any(r[3] is None for r in rows[-len(pids):]):
            break

    with open(os.path.join(a.out, "soak.csv.tmp"), "w") as f:
        f.write("cycle,node,pid,rss_kb,open_files,cycle_seconds,ok\n")
        for r in rows:
            f.write(",".join("" if v is None else str(v) for v in r) + "\n")
    os.replace(os.path.join(a.out, "soak.csv.tmp"), os.path.join(a.out, "soak.csv"))

    median = statistics.median(times)
    summary = {"cycles": len(times), "trajectory": a.trajectory, "failures": failures,
               "cycle_seconds": {"median": median, "max": max(times), "max_over_median": max(times) / median},
               "limits": {"max_slope_kb_per_cycle": a.max_slope_kb, "max_fd_growth": a.max_fd_growth,
                          "max_cycle_ratio": a.max_cycle_ratio, "warmup_cycles": a.warmup},
               "processes": {}}
    bad = list(failures)
    for node in pids:
        mine = [r for r in rows if r[1] == node and r[3] is not None]
        after = [r for r in mine if r[0] >= a.warmup]
        s = slope([r[0] for r in after], [r[3] for r in after])
        step = max(1, len(after) // 300)  # the pairwise median over at most 300 samples
        ts = theil_sen([r[0] for r in after[::step]], [r[3] for r in after[::step]])
        late = [r for r in mine if r[0] >= len(times) // 2]  # the second half: steps of the allocator vs a trend
        s_late = slope([r[0] for r in late], [r[3] for r in late])
        fd_growth = mine[-1][4] - mine[0][4] if mine else 0
        summary["processes"][node] = {"rss_kb_first": mine[0][3], "rss_kb_last": mine[-1][3],
                                      "rss_slope_kb_per_cycle": s, "rss_slope_second_half_kb_per_cycle": s_late,
                                      "rss_trend_kb_per_cycle": ts,
                                      "open_files_first": mine[0][4],
                                      "open_files_last": mine[-1][4]}
        if ts > a.max_slope_kb:
            bad.append({"why": "%s: RSS grows %.2f kB per cycle (Theil-Sen trend after the warm-up; limit %.1f)" % (
                node, ts, a.max_slope_kb)})
        if fd_growth > a.max_fd_growth:
            bad.append({"why": "%s: %d more open files than at the start" % (node, fd_growth)})
    if a.max_cycle_ratio > 0 and max(times) > a.max_cycle_ratio * median:
        bad.append({"why": "a cycle took %.2f s, %.2f x the median %.2f s" % (max(times), max(times) / median, median)})
    summary["verdict"] = "ok" if not bad else [b["why"] for b in bad]
    with open(os.path.join(a.out, "soak.json.tmp"), "w") as f:
        json.dump(summary, f, indent=2)
    os.replace(os.path.join(a.out, "soak.json.tmp"), os.path.join(a.out, "soak.json"))
    for node, p in summary["processes"].items():
        print("soak: %-22s RSS %7d -> %7d kB, trend %+.2f kB/cycle (least squares %+.2f, second half %+.2f), "
              "open files %d -> %d" % (node, p["rss_kb_first"], p["rss_kb_last"], p["rss_trend_kb_per_cycle"],
                                       p["rss_slope_kb_per_cycle"], p["rss_slope_second_half_kb_per_cycle"],
                                       p["open_files_first"], p["open_files_last"]))
    print("soak: %d cycles, median %.2f s, max %.2f s (%.2f x median), %d failures" % (
        len(times), median, max(times), max(times) / median, len(failures)))
    if bad:
        for b in bad:
            print("soak: FAILED: " + b["why"], file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
