"""Max fluid speed against time for the 2D tank at rest under the standard scheme and a
quiet one (README "Holding still", docs/validation.md "Holding still"). Input: the CSVs of
`runner export --csv RUN` for each run. LABEL names the quiet run (default: the preset).

Usage: python tools/plot_still_tank.py STANDARD.csv QUIET.csv OUT.png [LABEL]
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def series(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    t = [float(r["time_s"]) for r in rows[1:]]
    v = [float(r["max_speed_m_s"]) for r in rows[1:]]
    return t, v


def main():
    standard, quiet, out = sys.argv[1:4]
    quiet_label = sys.argv[4] if len(sys.argv) > 4 else "mps.preset: quiet"
    fig, ax = plt.subplots(figsize=(7, 4), dpi=120)
    for path, label in [(standard, "mps.pressure_scheme: standard"), (quiet, quiet_label)]:
        t, v = series(path)
        ax.semilogy(t, v, label=label)
    ax.axhline(0.017, color="grey", ls="--", lw=1, label="1 % of sqrt(gH)")
    ax.axhline(1e-3, color="grey", ls=":", lw=1, label="1 mm/s")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("max fluid speed (m/s)")
    ax.set_title("2D tank at rest, 1.0 x 0.3 m, 10 mm")
    ax.legend(loc="center right", fontsize=8)
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    main()
