#!/usr/bin/env python3
"""Reference least-squares Butterworth-Van Dyke fit of analyser sweeps (scipy), independent of
the probe's code: the fixture numbers bench/tests/analyze.rs compares `probe-bench analyze` with.

Model, in the physical parameters: Y = G0 + j w C0 + 1 / (R1 + j w L1 + 1/(j w C1)), fitted to
the real and imaginary parts of Y with equal weights (scipy.optimize.least_squares, 'lm',
parameters in units of their start values, residuals in units of the largest |Y|). f0 = 1 / (2 pi sqrt(L1 C1)), Q = w0 L1 / R1.

Start: f0 at the largest G, Q = 10, g = max G - min G, G0 = min G, C0 from a straight line
through B / w. sigma(f0) from (J^T J)^-1 times the residual variance, by the delta method.

Regenerate the fixture:
    python3 bench/tests/bvd_reference.py tests/data/heavy_c0 > tests/data/heavy_c0/scipy_bvd_fit.csv
"""
import glob
import os
import re
import sys

import numpy as np
from scipy.optimize import least_squares


def load(path):
    header = None
    rows = []
    truth = None
    with open(path) as fh:
        for line in fh:
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                m = re.search(r"f0 ([0-9.]+) Hz", s)
                if m:
                    truth = float(m.group(1))
                continue
            if header is None:
                header = [c.strip().lower() for c in s.split(",")]
                continue
            rows.append([float(c) for c in s.split(",")])
    a = np.array(rows)
    col = {c: k for k, c in enumerate(header)}
    f = a[:, col["freq_hz"]]
    if "y_re_s" in col:
        y = a[:, col["y_re_s"]] + 1j * a[:, col["y_im_s"]]
    else:
        z = a[:, col["z_mag_ohm"]] * np.exp(1j * np.radians(a[:, col["z_phase_deg"]]))
        y = 1.0 / z
    return f, y, truth


def model(p, w):
    g0, c0, r1, l1, c1 = p
    return g0 + 1j * w * c0 + 1.0 / (r1 + 1j * w * l1 + 1.0 / (1j * w * c1))


def fit(f, y):
    w = 2 * np.pi * f
    k = int(np.argmax(y.real))
    w0 = w[k]
    q = 10.0
    g = y.real.max() - y.real.min()
    r1 = 1.0 / g
    l1 = q * r1 / w0
    c1 = 1.0 / (w0 * w0 * l1)
    c0 = np.polyfit(w, y.imag, 1)[0]
    p0 = np.array([y.real.min(), c0, r1, l1, c1])

    # Fitted in units of the start (p = p0 x) and of the largest |Y|: all of order one.
    ys = np.abs(y).max()

    def res(x):
        d = (model(p0 * x, w) - y) / ys
        return np.concatenate([d.real, d.imag])

    r = least_squares(res, np.ones(5), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                      max_nfev=20000)
    p = p0 * r.x
    _, _, r1, l1, c1 = p
    f0 = 1.0 / (2 * np.pi * np.sqrt(l1 * c1))
    q = 2 * np.pi * f0 * l1 / r1
    dof = max(2 * len(f) - 5, 1)
    s2 = float(np.sum(r.fun ** 2)) / dof
    cov = np.linalg.inv(r.jac.T @ r.jac) * s2
    # f0 = (L1 C1)^(-1/2) / 2pi: gradient in the scaled (x_L1, x_C1) is -f0/2 each.
    grad = np.array([0, 0, 0, -0.5 * f0 / r.x[3], -0.5 * f0 / r.x[4]])
    sigma = float(np.sqrt(grad @ cov @ grad))
    return f0, sigma, q, r.status


def main():
    d = sys.argv[1]
    print(f"# {os.path.basename(__file__)} (scipy {__import__('scipy').__version__}, "
          f"numpy {np.__version__}): least-squares BVD fit of each capture")
    print("file,f0_true_hz,f0_scipy_hz,sigma_f0_scipy_hz,q_scipy,error_hz")
    for path in sorted(glob.glob(os.path.join(d, "hc0_*.csv"))):
        f, y, truth = load(path)
        f0, sigma, q, status = fit(f, y)
        assert status > 0, (path, status)
        print(f"{os.path.basename(path)},{truth},{f0:.6f},{sigma:.6f},{q:.4f},{f0 - truth:.6f}")


if __name__ == "__main__":
    main()
