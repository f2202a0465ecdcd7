#!/usr/bin/env python3
"""How fast should a 2D Bingham heap still creep? A thin-layer (lubrication) check of a run.

Reads a finished column-collapse run (MCAP), takes the concrete's free surface h(x) at
--from-s (the highest fluid particle per l0-wide column, plus l0/2), and carries it on in
time with the thin-layer equation of a Bingham fluid on a no-slip floor (Liu & Mei 1989;
Balmforth, Craster & Sassi 2002):

    h_t + q_x = 0,  q = rho g S Y^2 (3h - Y) / (6 mu),  S = -h_x,  Y = h - tau_y / (rho g S),

q = 0 where Y <= 0 (no yielded layer), no flux through the wall at x = 0. Its rest state is
the closed form h = sqrt(2 tau_y d / (rho g)). The output is a table of the run's front
beside this model's front at the run's later diagnostics times, both as distances past the
run's front at --from-s, so a reader sees whether the run's slow approach to the closed form
is the Bingham fluid's own (same pace) or a numerical one.

The fluid (density, yield stress, plastic viscosity), gravity and spacing come from the run's
stored manifest. docs/validation.md (Bingham heap) quotes its tables.

Usage: .venv/bin/python tools/heap_lubrication.py RUN.mcap [--from-s 10] [--every-s 10]
"""
import argparse
import json
import math
import struct
import sys
import os

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import check_mcap  # noqa: E402  (the project's MCAP reader)

FLUID_KIND = 0.0


def clouds_and_rows(path):
    run = check_mcap.read_complete(path)
    clouds, rows = [], []
    for ch, msg, dec in run.messages:
        if ch.topic == "/particles":
            clouds.append((msg.log_time * 1e-9, dec))
        elif ch.topic == "/diagnostics":
            rows.append((msg.log_time * 1e-9, dec))
    manifest = json.loads(run.metadata["manifest"]["canonical"])
    return manifest, clouds, rows


def surface(pc, l0):
    """h per l0-wide column from x = 0: highest fluid particle + l0/2 (0 where none)."""
    f = {fl.name: fl.offset for fl in pc.fields}
    n = len(pc.data) // pc.point_stride
    tops = {}
    count = 0
    for i in range(n):
        base = i * pc.point_stride
        kind = struct.unpack_from("<f", pc.data, base + f["kind"])[0]
        if kind != FLUID_KIND:
            continue
        count += 1
        x = struct.unpack_from("<f", pc.data, base + f["x"])[0]
        y = struct.unpack_from("<f", pc.data, base + f["y"])[0]
        j = int(math.floor(x / l0))
        tops[j] = max(tops.get(j, -1.0), y)
    m = max(tops) + 1
    h = [tops[j] + 0.5 * l0 if j in tops else 0.0 for j in range(m)]
    # Scale to the particles' own area (count x l0^2): the tops overstate it by up to l0/2.
    scale = count * l0 * l0 / (sum(h) * l0)
    return [v * scale for v in h]


def front(h, dx):
    last = max((i for i, v in enumerate(h) if v > 0.0), default=-1)
    return (last + 1) * dx


def step(h, dx, rho_g, tau, mu, t_end):
    """Explicit finite volumes, the time step from the flux's slope dq/dS (stable to 0.4)."""
    n = len(h)
    t = 0.0
    k = tau / rho_g
    while t < t_end:
        q = [0.0] * (n + 1)  # q[i] is the flux through the face left of cell i
        d_max = 1e-12
        for i in range(1, n):
            s = -(h[i] - h[i - 1]) / dx
            hf = 0.5 * (h[i] + h[i - 1])
            a = abs(s)
            if a == 0.0 or hf <= 0.0:
                continue
            y = hf - k / a
            if y <= 0.0:
                continue
            q[i] = math.copysign(rho_g * a * y * y * (3.0 * hf - y) / (6.0 * mu), s)
            d_max = max(d_max, rho_g * (6 * hf * hf * y - 6 * hf * y * y + 2 * y ** 3) / (6 * mu))
        dt = min(0.4 * dx * dx / d_max, t_end - t)
        for i in range(n):
            h[i] -= dt * (q[i + 1] - q[i]) / dx
        t += dt
    return h


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("--from-s", type=float, default=10.0)
    ap.add_argument("--every-s", type=float, default=10.0)
    ap.add_argument("--refine", type=int, default=2, help="model cells per spacing")
    a = ap.parse_args()
    manifest, clouds, rows = clouds_and_rows(a.run)
    fluid = manifest["fluid"]
    if manifest["dimension"] != 2 or manifest["scene"]["kind"] != "column_collapse":
        sys.exit("heap_lubrication: a 2D column_collapse run is needed")
    tau = fluid["yield_stress_pa"]
    mu = fluid["plastic_viscosity_pa_s"]
    t0, pc = min(clouds, key=lambda c: abs(c[0] - a.from_s))
    l0 = manifest["spacing_m"]
    # Model cells of l0 / refine (the front moves in whole cells), room to spread behind.
    dx = l0 / a.refine
    h = [v for v in surface(pc, l0) for _ in range(a.refine)]
    h += [0.0] * len(h)
    rho_g = fluid["density_kg_m3"] * manifest["gravity_m_s2"]
    runs_front = [(t, d.metrics["heap_length_m"]) for t, d in rows]
    _, f0 = min(runs_front, key=lambda r: abs(r[0] - t0))
    print(f"# surface at t = {t0:.3f} s: {sum(v > 0 for v in h)} cells of {dx} m, "
          f"run's heap length {f0:.4f} m")
    print("| t (s) | run: heap length (m) | run: gain (mm) | thin layer: gain (mm) |")
    print("|---|---|---|---|")
    base = front(h, dx)
    t = t0
    while t + a.every_s <= runs_front[-1][0] + 0.5 * a.every_s:
        h = step(h, dx, rho_g, tau, mu, a.every_s)
        t += a.every_s
        _, f = min(runs_front, key=lambda r: abs(r[0] - t))
        print(f"| {t:.1f} | {f:.4f} | {1000 * (f - f0):.1f} | {1000 * (front(h, dx) - base):.1f} |")
    k = tau / rho_g
    area = sum(h) * dx
    print(f"# thin layer's front at {t:.1f} s: {f0 + front(h, dx) - base:.4f} m; closed-form "
          f"rest length for the area {area:.4f} m2: {(1.5 * area) ** (2 / 3) / (2 * k) ** (1 / 3):.4f} m")


if __name__ == "__main__":
    main()
