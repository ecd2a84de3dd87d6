"""Regenerate ``app/data/example_nox.csv``, the small log shipped for the first-run demo.

A 150 s drive at 50 Hz over the SKF paper's 12×18 NOx grid (SKF (34)): engine speed and fuel
follow smoothed random steps, NOx comes from :func:`estimation.plants.nox.simulate_nox`
(drifting true map, 38-sample delay, lag a = 0.96, σv = 25 ppm). Deterministic (seed 7).

    python scripts/make_example_log.py
"""

from pathlib import Path

import numpy as np

from estimation.plants.nox import simulate_nox

RATE_HZ = 50.0
DURATION_S = 150.0
OUT = Path(__file__).resolve().parents[1] / "app" / "data" / "example_nox.csv"


def smoothed_steps(rng: np.random.Generator, n: int, lo: float, hi: float, hold: int) -> np.ndarray:
    """Random set-points held for ``hold`` samples, smoothed by a first-order filter."""
    targets = np.repeat(rng.uniform(lo, hi, size=n // hold + 1), hold)[:n]
    out = np.empty(n)
    out[0] = targets[0]
    alpha = 0.03
    for k in range(1, n):
        out[k] = out[k - 1] + alpha * (targets[k] - out[k - 1])
    return out


def main() -> None:
    rng = np.random.default_rng(7)
    n = int(DURATION_S * RATE_HZ)
    time_s = np.arange(n) / RATE_HZ
    speed = smoothed_steps(rng, n, 800.0, 4200.0, hold=150)
    fuel = smoothed_steps(rng, n, 0.0, 75.0, hold=60)
    signals, _ = simulate_nox(time_s, speed, fuel, seed=7)
    with OUT.open("w") as f:
        f.write("time [s],speed_rpm [rpm],fuel_mg_per_stroke [mg/stroke],nox_ppm [ppm]\n")
        for k in range(n):
            f.write(
                f"{time_s[k]:.2f},{signals['speed_rpm'][k]:.1f},"
                f"{signals['fuel_mg_per_stroke'][k]:.2f},{signals['nox_ppm'][k]:.1f}\n"
            )
    print(f"wrote {OUT} ({n} samples)")


if __name__ == "__main__":
    main()
