"""Speed of ``identify`` (IDIM-LS plus every IDIM-ILIC window) on a 1-hour 1 kHz log.

Prints wall and CPU times and their ratios against a straightforward SciPy
implementation of the same computation run in the same process. Never
asserted by tests: run it with ``make bench``.
"""

from __future__ import annotations

import time

import numpy as np


def synthetic_hour(fs: float = 1000.0, hours: float = 1.0) -> dict[str, np.ndarray]:
    """A 1-hour exciting run (3.6 M samples) with the paper's parameters and noise."""
    n = int(3600 * hours * fs)
    t = np.arange(n) / fs
    w = 2 * np.pi / 6.2
    q_ref = 0.08 * np.sin(w * t) + 0.03 * np.sin(3 * w * t)
    qd_ref = 0.08 * w * np.cos(w * t) + 0.09 * w * np.cos(3 * w * t)
    qdd_ref = -0.08 * w**2 * np.sin(w * t) - 0.27 * w**2 * np.sin(3 * w * t)
    rng = np.random.default_rng(0)
    tau = 95 * qdd_ref + 200 * qd_ref + 20 * np.sign(qd_ref) - 3 + rng.normal(0, 1, n)
    q = q_ref + rng.normal(0, 2e-7, n)
    return {"t": t, "q": q, "q_ref": q_ref, "qd_ref": qd_ref, "qdd_ref": qdd_ref, "tau": tau}


def ours(d: dict[str, np.ndarray], fs: float) -> tuple[float, float]:
    from ilic_cli.idim_ilic import ILICSettings, identify_ilic
    from ilic_cli.idim_ls import idim_ls
    from ilic_cli.regressor import get_model

    model = get_model("rigid-offset")
    t0, c0 = time.perf_counter(), time.process_time()
    idim_ls(d["t"], d["q"], d["tau"], fs, model)
    identify_ilic(d["t"], d["q_ref"], d["tau"], fs, model, ILICSettings(), qd_ref=d["qd_ref"], qdd_ref=d["qdd_ref"], q=d["q"])
    return time.perf_counter() - t0, time.process_time() - c0


def baseline(d: dict[str, np.ndarray], fs: float) -> tuple[float, float]:
    """Straightforward SciPy: filtfilt, gradient, decimate per column, lstsq per window."""
    from scipy import signal

    t0, c0 = time.perf_counter(), time.process_time()
    b, a = signal.butter(4, 100 / (fs / 2))
    qf = signal.filtfilt(b, a, d["q"])
    qd = np.gradient(qf, 1 / fs)
    qdd = np.gradient(qd, 1 / fs)
    W = np.column_stack([qdd, qd, np.sign(qd), np.ones_like(qd)])[49:]
    y = d["tau"][49:]
    Wd = np.column_stack([signal.decimate(c, 10) for c in W.T])
    yd = signal.decimate(y, 10)
    np.linalg.lstsq(Wd, yd, rcond=None)
    n = int(6.2 * fs)
    for k in range(len(y) // n):
        s = slice(k * n, (k + 1) * n)
        Wr = np.column_stack([d["qdd_ref"][s], d["qd_ref"][s], np.sign(d["qd_ref"][s]), np.ones(n)])
        Wr = signal.decimate(signal.decimate(Wr, 8, axis=0), 10, axis=0)
        yr = signal.decimate(signal.decimate(d["tau"][s], 8), 10)
        theta, *_ = np.linalg.lstsq(Wr, yr, rcond=None)
        e = yr - Wr @ theta
        np.sqrt(np.diag(np.linalg.inv(Wr.T @ Wr)) * (e @ e) / (len(yr) - 4))
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    fs = 1000.0
    d = synthetic_hour(fs)
    ours(d, fs)  # warm-up (imports)
    t_ours, c_ours = min(ours(d, fs) for _ in range(3))
    t_base, c_base = min(baseline(d, fs) for _ in range(2))
    n = len(d["t"])
    print(f"identify, 1-hour 1 kHz log ({n} samples), IDIM-LS + {n // 6200} IDIM-ILIC windows (best of runs; CPU = this process, all threads):")
    print(f"  ours      {t_ours:6.3f} s wall  {c_ours:6.3f} s cpu   ({3600 / t_ours:8.0f}x real time)")
    print(f"  baseline  {t_base:6.3f} s wall  {c_base:6.3f} s cpu   (straightforward scipy)")
    print(f"  speed-up  {t_base / t_ours:6.2f}x wall  {c_base / c_ours:6.2f}x cpu")


if __name__ == "__main__":
    main()
