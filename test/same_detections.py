#!/usr/bin/env python3
"""Two detections files (model_matching's format) hold the same parts: the same count (at least
one), names and models, positions and quaternions within TOL (m; unitless for the quaternion),
fitness within 1e-9, the same passes (their roles in order). Usage: same_detections.py A.json B.json TOL. Exit 0 same, 1 different."""
import json
import sys


def main():
    a_path, b_path, tol = sys.argv[1], sys.argv[2], float(sys.argv[3])
    ja, jb = json.load(open(a_path)), json.load(open(b_path))
    a, b = ja["detections"], jb["detections"]
    print("same_detections: %d in %s, %d in %s" % (len(a), a_path, len(b), b_path))
    if ja.get("passes", []) != jb.get("passes", []):
        print("different: passes %s against %s" % (ja.get("passes"), jb.get("passes")))
        return 1
    if not a or len(a) != len(b):
        print("different: %d against %d detections (at least one needed)" % (len(a), len(b)))
        return 1
    worst = 0.0
    bad = []
    for da, db in zip(sorted(a, key=lambda d: d["name"]), sorted(b, key=lambda d: d["name"])):
        if (da["name"], da["model"]) != (db["name"], db["model"]):
            bad.append("%s (%s) against %s (%s)" % (da["name"], da["model"], db["name"], db["model"]))
            continue
        dev = max([abs(x - y) for x, y in zip(da["xyz"], db["xyz"])] + [abs(x - y) for x, y in zip(da["quat"], db["quat"])])
        worst = max(worst, dev)
        if dev > tol or abs(da["fitness"] - db["fitness"]) > 1e-9:
            bad.append("%s: pose differs by %.3g, fitness %.6f against %.6f" % (da["name"], dev, da["fitness"], db["fitness"]))
    print("same_detections: largest difference %.3g (limit %.3g)" % (worst, tol))
    for line in bad:
        print("different: " + line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
