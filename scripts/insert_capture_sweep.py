#!/usr/bin/env python3
"""The insert's capture region, measured (docs/control.md, "Capture region, measured").

Writes one batch for `foresight-remote simulate-insertions` (the controller's
insert on the simulated plant, in-process), runs it, and prints for each swept
error the largest value from which every smaller one succeeds:
  lateral  0-9 mm (0.25 mm steps, 0.1 mm from 6 mm), 12 directions, tilt 0, 10 mm in front
  tilt     0-7 deg (0.25 deg steps), axes at 0, 90, 225 deg, on the axis, 5 mm and 10 mm in front
  axial    -16 .. +6 mm (0.05 mm steps around -10 mm), on the axis, untilted

    python3 scripts/insert_capture_sweep.py [--remote build/bin/foresight-remote] [--keep DIR]
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile


def pose(x=0.0, y=0.0, z=-0.01, tilt_deg=0.0, axis_deg=0.0):
    """tag_T_tip rows: translation (x, y, z), tilt about the in-plane axis at axis_deg."""
    a = math.radians(tilt_deg)
    ux, uy, uz = math.cos(math.radians(axis_deg)), math.sin(math.radians(axis_deg)), 0.0
    c, s, C = math.cos(a), math.sin(a), 1.0 - math.cos(a)
    R = [[c + ux * ux * C, ux * uy * C - uz * s, ux * uz * C + uy * s],
         [uy * ux * C + uz * s, c + uy * uy * C, uy * uz * C - ux * s],
         [uz * ux * C - uy * s, uz * uy * C + ux * s, c + uz * uz * C]]
    return [R[0] + [x], R[1] + [y], R[2] + [z], [0.0, 0.0, 0.0, 1.0]]


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--remote", default=os.path.join(here, "..", "build", "bin", "foresight-remote"))
    ap.add_argument("--keep", help="write the batch and the results into this folder")
    args = ap.parse_args()

    trials, sweeps = [], {}

    def add(sweep, value, **kw):
        trials.append({"id": len(trials), "tag_T_tip": pose(**kw)})
        sweeps.setdefault(sweep, []).append((value, len(trials) - 1))

    lateral_mm = [k * 0.25 for k in range(24)] + [6.0 + k * 0.1 for k in range(31)]
    for ang in range(0, 360, 30):
        for r in lateral_mm:
            add(("lateral mm", "direction %d deg" % ang), r,
                x=r * 1e-3 * math.cos(math.radians(ang)), y=r * 1e-3 * math.sin(math.radians(ang)))
    for z in (-0.005, -0.010):
        for axis in (0, 90, 225):
            for k in range(29):
                add(("tilt deg", "axis %d deg, %g mm in front" % (axis, -z * 1e3)), k * 0.25,
                    z=z, tilt_deg=k * 0.25, axis_deg=axis)
    axial_mm = sorted(set([-16 + k * 0.5 for k in range(45)] + [-10.5 + k * 0.05 for k in range(21)]))
    for z in axial_mm:
        add(("axial mm", "descending from +6 mm"), -z, z=z * 1e-3)  # swept from +6 down: value = -z

    folder = args.keep or tempfile.mkdtemp(prefix="insert_capture_")
    os.makedirs(folder, exist_ok=True)
    batch = os.path.join(folder, "batch.json")
    with open(batch, "w") as f:
        json.dump({"trials": trials}, f)
    run = subprocess.run([args.remote, "simulate-insertions", "--json", "--batch", batch],
                         capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(run.stderr.strip() or "foresight-remote failed (%d)" % run.returncode)
    out = json.loads(run.stdout)
    if args.keep:
        with open(os.path.join(folder, "results.json"), "w") as f:
            f.write(run.stdout)
    ok = {r["id"]: r for r in out["results"]}
    print("%d insertions, %.1f s compute" % (out["trials"], out["compute_s"]))
    for (what, where), points in sweeps.items():
        points.sort()
        edge, first_fail = None, None
        for value, i in points:
            if ok[i]["success"]:
                edge = value
            else:
                first_fail = (value, ok[i]["reason"])
                break
        if what == "axial mm":
            edge = None if edge is None else -edge
            print("axial mm, %s: deepest start in front that succeeds %s mm (first failure %s mm, %s)" %
                  (where, edge, -first_fail[0] if first_fail else None, first_fail[1] if first_fail else "-"))
        else:
            print("%s, %s: largest that succeeds %s (first failure %s)" % (what, where, edge, first_fail))


if __name__ == "__main__":
    main()
