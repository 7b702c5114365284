#!/usr/bin/env python3
"""The base fit the way a calibration engineer would script it (the peer of `crosscal fit`).

Reads a crosscal session (manifest + CSVs) with pandas, builds the reference conic motion
(paper eqs. 1-2, spec sign) in sensor axes, the default model's regressors (gyro: bias,
C_omega, C_epsilon; accelerometer: bias, K) and solves each sensor with numpy.linalg.lstsq.
Prints the coefficients as JSON. Written for the benchmark: straightforward, vectorised.

usage: fit_numpy.py SESSION.json
"""
import json
import math
import os
import sys

import numpy as np
import pandas as pd

AXIS = {"x": 0, "y": 1, "z": 2}


def mount_matrix(names):
    m = np.zeros((3, 3))
    for i, n in enumerate(names):
        m[i, AXIS[n[1]]] = -1.0 if n[0] == "-" else 1.0
    return m


def main(path):
    with open(path) as f:
        man = json.load(f)
    base = os.path.dirname(path)
    g = man.get("stand", {}).get("g", 9.80665)
    units = man["units"]
    kg = math.pi / 180.0 if units["gyro"] == "deg/s" else 1.0
    ka = g if units["accel"] == "g" else 1.0
    xg, yg, xa, ya = [], [], [], []
    for run in man["runs"]:
        mo = run["motion"]
        if mo["kind"] != "conic":
            continue
        df = pd.read_csv(os.path.join(base, run["file"]), comment="#")
        t = df["t"].to_numpy()
        al = math.radians(mo["cone_angle_deg"])
        ws = math.radians(mo["rate_deg_s"])
        th = ws * t + math.radians(mo.get("phase_deg", 0.0))
        sa, ca = math.sin(al), math.cos(al)
        st, ct = np.sin(th), np.cos(th)
        w = np.stack([ws * sa * ct, -ws * sa * st, np.full_like(t, ws * (1 - ca))], axis=1)
        e = np.stack([-ws * ws * sa * st, -ws * ws * sa * ct, np.zeros_like(t)], axis=1)
        a = np.stack([-g * sa * ct, g * sa * st, np.full_like(t, g * ca)], axis=1)
        m = mount_matrix(run["mount"])
        w, e, a = w @ m.T, e @ m.T, a @ m.T
        one = np.ones((len(t), 1))
        xg.append(np.hstack([one, w, e]))
        xa.append(np.hstack([one, a]))
        yg.append(df[["gx", "gy", "gz"]].to_numpy() * kg)
        ya.append(df[["ax", "ay", "az"]].to_numpy() * ka)
    out = {}
    for name, x, y in (("gyro", xg, yg), ("accel", xa, ya)):
        x, y = np.vstack(x), np.vstack(y)
        theta, res, rank, sv = np.linalg.lstsq(x, y, rcond=None)
        out[name] = theta.T.tolist()
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main(sys.argv[1])
