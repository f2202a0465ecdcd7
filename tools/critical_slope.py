#!/usr/bin/env python3
"""At what surface slope does a yield-stress material draining through a rock bed stop?

A heap in a bed drains slowly towards rest, so a run's slope at its time cap is not the
slope at rest. This asks the state itself: it restarts the run from one checkpoint with
gravity scaled by each factor f (`examples/step_from ... gravity_m_s2=f g`), measures how
fast the front moves along the floor (`floor_reach_m`, over the last 3 of 4 s), and fits
the plane Bingham slot law to the speeds,

    v(f) = c + K f (1 - a)^2 (1 + a / 2),   a = min(f* / f, 1),

the flux of a Bingham fluid through a slit (Bird, Dai & Yarusso 1983) whose driving
gradient rho f g S meets its threshold at f = f*; c is what still moves below it (the
scheme's creep). The state stops under gravity f* g, so under g its surface would stand at
the critical slope S_c = f* S, S the run's `surface_slope` at the checkpoint. The output
sets S_c beside the hydraulic-radius estimate (`closed_form_surface_slope`, tau_0 / (rho g
R_h)) and, for a bed with a gap w between rocks (`scene.bed.gap_m` > 0), beside the slit's
own threshold 2 tau_0 / (rho g w) (docs/rockfill.md, "Where the drain stops"). g, tau_0, rho
and w come from the run's stored manifest.

Usage: .venv/bin/python tools/critical_slope.py RUN.mcap --at T_S [--factors 0.4,0.6,...]
           [--runner target/release/runner] [--step-from target/release/examples/step_from]
       .venv/bin/python tools/critical_slope.py --self-test   (the fit recovers a known
           threshold)
The readers of tools/requirements.txt (the venv tools/test.sh makes); the binaries from
`cargo build --release --examples --bins`.
"""
import argparse
import csv
import io
import json
import os
import re
import subprocess
import sys


def slot_flux(f, f_star):
    """The slit law's shape: f (1 - a)^2 (1 + a/2), a = min(f*/f, 1) (0 at and below f*)."""
    a = min(f_star / f, 1.0)
    return f * (1.0 - a) ** 2 * (1.0 + a / 2.0)


def fit(points):
    """Least squares of v = c + K slot_flux(f, f*) over f* on a 0.001 grid (c, K linear).

    Returns (f_star, K, c, rms) for the best f* with K > 0, or None."""
    best = None
    n = len(points)
    sv = sum(v for _, v in points)
    for k in range(1, 3000):
        f_star = k * 0.001
        b = [slot_flux(f, f_star) for f, _ in points]
        sb, sbb = sum(b), sum(x * x for x in b)
        sbv = sum(x * v for x, (_, v) in zip(b, points))
        det = n * sbb - sb * sb
        if det <= 0.0:
            continue
        big_k = (n * sbv - sb * sv) / det
        c = (sv - big_k * sb) / n
        if big_k <= 0.0:
            continue
        r = sum((c + big_k * x - v) ** 2 for x, (_, v) in zip(b, points))
        if best is None or r < best[3]:
            best = (f_star, big_k, c, r)
    if best is None:
        return None
    f_star, big_k, c, r = best
    return f_star, big_k, c, (r / n) ** 0.5


def diagnostics_row(runner, run, at_s):
    """The run's diagnostics row nearest to at_s (runner export --csv)."""
    text = subprocess.run(
        [runner, "export", "--csv", run], check=True, capture_output=True, text=True
    ).stdout
    rows = list(csv.DictReader(io.StringIO(text)))
    return min(rows, key=lambda r: abs(float(r["time_s"]) - at_s))


def front_speed_mm_s(step_from, run, at_s, factor, g):
    """The front's advance along the floor over the last 3 s of 4 under gravity factor g, and
    the time of the checkpoint the restart began from."""
    out = subprocess.run(
        [step_from, run, "--at", str(at_s), "--for", "4", "--every", "1",
         "--metric", "floor_reach_m", f"gravity_m_s2={factor * g!r}"],
        check=True, capture_output=True, text=True,
    ).stdout
    start = float(re.search(r"# from t = (\S+) s", out).group(1))
    reach = [float(line.split()[-1]) for line in out.splitlines() if "floor_reach_m" in line]
    if len(reach) < 4:
        return None, start  # the step failed (the state blew up): no speed
    return (reach[3] - reach[0]) / 3.0 * 1000.0, start


def stored_manifest(run):
    """The run's canonical manifest, read with the project's MCAP reader."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import check_mcap  # noqa: E402  (needs tools/requirements.txt)

    return json.loads(check_mcap.read_complete(run).metadata["manifest"]["canonical"])


def self_test():
    """Synthetic speeds from a known law, with and without a floor, must give back f*."""
    for f_star, big_k, c in ((0.5, 10.0, 0.0), (0.75, 6.0, 0.3), (1.2, 4.0, 0.1)):
        factors = [0.4, 0.5, 0.6, 0.75, 0.9, 1.0, 1.25, 1.5, 2.0]
        points = [(f, c + big_k * slot_flux(f, f_star)) for f in factors]
        got = fit(points)
        assert got is not None and abs(got[0] - f_star) <= 0.002, (f_star, got)
        assert abs(got[1] - big_k) <= 0.05 * big_k and abs(got[2] - c) <= 0.02, (big_k, c, got)
    print("critical_slope self-test: ok")


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("run", nargs="?")
    p.add_argument("--at", type=float)
    p.add_argument("--factors", default="0.3,0.4,0.5,0.6,0.75,1.0,1.25,1.5")
    p.add_argument("--runner", default="target/release/runner")
    p.add_argument("--step-from", default="target/release/examples/step_from")
    p.add_argument("--self-test", action="store_true")
    a = p.parse_args()
    if a.self_test:
        self_test()
        return 0
    if a.run is None or a.at is None:
        p.error("RUN.mcap and --at are needed (or --self-test)")
    try:
        factors = [float(x) for x in a.factors.split(",")]
    except ValueError:
        p.error(f"--factors {a.factors!r}: not a comma-separated list of numbers")
    if len(factors) < 4 or min(factors) <= 0.0:
        p.error("--factors needs at least four factors (the fit has three unknowns), each above 0")
    try:
        return scan(a, factors)
    except subprocess.CalledProcessError as e:
        print(f"critical_slope: {' '.join(e.cmd[:2])} failed:\n{e.stderr}", file=sys.stderr)
    except KeyError as e:
        print(f"critical_slope: {a.run} has no {e} (not a rock-fill run?)", file=sys.stderr)
    except OSError as e:
        print(f"critical_slope: {e}", file=sys.stderr)
    return 2


def scan(a, factors):
    """The scan over `factors`, the fit and the comparison, printed; 0, or 1 without a fit."""
    m = stored_manifest(a.run)
    g = float(m["gravity_m_s2"])
    print("factor  front_speed_mm_s")
    points, start = [], None
    for f in factors:
        v, start = front_speed_mm_s(a.step_from, a.run, a.at, f, g)
        print(f"{f:.3f}  {'failed' if v is None else f'{v:.3f}'}")
        if v is not None:
            points.append((f, v))
    # The slope of the state the restarts began from.
    row = diagnostics_row(a.runner, a.run, start)
    slope = float(row["surface_slope"])
    estimate = float(row["closed_form_surface_slope"])
    print(f"# {a.run}, the checkpoint at t = {start:.4f} s: surface slope {slope:.4f}, "
          f"hydraulic-radius estimate {estimate:.4f}")
    got = fit(points) if len(points) >= 4 else None
    if got is None:
        print("no threshold: fewer than four restarts ran, or the speeds do not rise with "
              "gravity as a slit's flux does")
        return 1
    f_star, big_k, c, rms = got
    critical = f_star * slope
    print(f"threshold f* {f_star:.3f} (K {big_k:.2f} mm/s, floor {c:.2f} mm/s, rms {rms:.2f})")
    print(f"critical slope {critical:.4f}: {critical / estimate:.2f} x the hydraulic-radius "
          f"estimate {estimate:.4f}", end="")
    gap = float(m["scene"].get("bed", {}).get("gap_m", 0.0))
    fluid = m["fluid"]
    if gap > 0.0 and "yield_stress_pa" in fluid:
        slit = 2.0 * float(fluid["yield_stress_pa"]) / (float(fluid["density_kg_m3"]) * g * gap)
        print(f", {critical / slit:.2f} x the slit's 2 tau_0 / (rho g w) = {slit:.4f}")
    else:
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
