#!/usr/bin/env python3
"""How fast should a Bingham heap still creep? A thin-layer (lubrication) check of a run.

Reads a finished run (MCAP) of a 2D column collapse or a 3D slump flow, takes the concrete's
free surface at --from-s (the highest fluid particle per l0-wide column, or per l0-wide ring
around the slump's axis, plus l0/2, scaled to the particles' own area or volume), and
carries it on in time with the thin-layer equation of a Bingham fluid on a no-slip floor
(Liu & Mei 1989; Balmforth, Craster & Sassi 2002; axisymmetric: Balmforth et al. 2006):

    h_t + q_x = 0            (plane),   h_t + (1/r) (r q)_r = 0   (axisymmetric),
    q = rho g S Y^2 (3h - Y) / (6 mu),  S = -h_x,  Y = h - tau_y / (rho g S),

q = 0 where Y <= 0 (no yielded layer), no flux through the wall at x = 0 (or the axis).
Its rest state is the closed form h = sqrt(2 tau_y d / (rho g)), d the distance back from
the front (the heap's law; the slump's pancake law). The output is a table of the run's
front (heap length, or mean spread radius) beside this model's at the run's later
diagnostics times, both as distances past the run's front at --from-s, so a reader sees
whether the run's approach to rest is the Bingham fluid's own (same pace) or a numerical
one; then, with --until-s, the model carried on past the run's end to when its largest
surface speed rho g S Y^2 / (2 mu) falls below --rest-m-s.

The fluid (density, yield stress, plastic viscosity), gravity and spacing come from the run's
stored manifest. docs/validation.md (Bingham heap; Low yield stresses) quotes its tables.

Usage: .venv/bin/python tools/heap_lubrication.py RUN.mcap [--from-s 10] [--every-s 10]
           [--until-s 300] [--rest-m-s 1e-4] [--refine 2]
       .venv/bin/python tools/heap_lubrication.py --self-test   (the model against its closed
           forms; tests/integration/column_collapse.rs runs it)
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


def surface(pc, l0, axisymmetric, copies):
    """h per l0-wide column from x = 0 (or ring from the axis): highest fluid particle +
    l0/2, 0 where none, scaled to the particles' own area (count l0^2) or volume (copies x
    count l0^3, copies = 4 for a quarter domain): the tops overstate it by up to l0/2."""
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
        x, y = struct.unpack_from("<ff", pc.data, base + f["x"])
        if axisymmetric:
            z = struct.unpack_from("<f", pc.data, base + f["z"])[0]
            key, top = int(math.floor(math.hypot(x, y) / l0)), z
        else:
            key, top = int(math.floor(x / l0)), y
        tops[key] = max(tops.get(key, -1.0), top)
    m = max(tops) + 1
    h = [tops[j] + 0.5 * l0 if j in tops else 0.0 for j in range(m)]
    # A ring at the axis that holds no particle centre (they lie off the axis) is no hole.
    first = min(tops)
    h[:first] = [h[first]] * first
    own = copies * count * l0 ** 3 if axisymmetric else count * l0 * l0
    held = amount(h, l0, axisymmetric)
    return [v * own / held for v in h]


def amount(h, dx, axisymmetric):
    """The layer's area (plane, per unit width) or volume (axisymmetric: cell j is the ring
    from j dx to (j + 1) dx)."""
    if axisymmetric:
        return sum(v * math.pi * ((j + 1) ** 2 - j ** 2) * dx * dx for j, v in enumerate(h))
    return sum(h) * dx


def front(h, dx):
    """The end of the body: the first empty cell from the wall (or axis) on. A particle that
    has come loose and slides on ahead (which sets the run's own front metric) is not part
    of the layer."""
    first_empty = next((i for i, v in enumerate(h) if v <= 0.0), len(h))
    return first_empty * dx


def step(h, dx, rho_g, tau, mu, t_end, axisymmetric):
    """Explicit finite volumes, the time step from the flux's slope dq/dS (stable to 0.4).
    Returns the surface and the largest surface speed at the end, u_s = rho g S Y^2 / (2 mu)
    (the top of the velocity profile, Liu & Mei 1989)."""
    n = len(h)
    t = 0.0
    k = tau / rho_g
    # Face i lies at x = i dx (left of cell i); a ring's flux scales with its circumference.
    face = [i * dx if axisymmetric else 1.0 for i in range(n + 1)]
    cell = [(i + 0.5) * dx if axisymmetric else 1.0 for i in range(n)]
    u_max = 0.0
    while t < t_end:
        u_max = 0.0
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
            q[i] = face[i] * math.copysign(rho_g * a * y * y * (3.0 * hf - y) / (6.0 * mu), s)
            u_max = max(u_max, rho_g * a * y * y / (2.0 * mu))
            d_max = max(d_max, rho_g * (6 * hf * hf * y - 6 * hf * y * y + 2 * y ** 3) / (6 * mu))
        dt = min(0.4 * dx * dx / d_max, t_end - t)
        for i in range(n):
            h[i] -= dt * (q[i + 1] - q[i]) / (dx * cell[i])
        t += dt
    return h, u_max


def rest_front(h, dx, k, axisymmetric):
    """The closed form's front for the model's area (plane) or volume (axisymmetric)."""
    if axisymmetric:
        # V = 2 pi int_0^R sqrt(2 k (R - r)) r dr = (8 pi / 15) sqrt(2 k) R^(5/2).
        return (15.0 * amount(h, dx, True) / (8.0 * math.pi * math.sqrt(2.0 * k))) ** 0.4
    return (1.5 * amount(h, dx, False)) ** (2 / 3) / (2 * k) ** (1 / 3)


def self_test():
    """The model alone: a block of 0.1 m (0.2 m long, or 0.2 m in radius) of a Bingham fluid
    (tau_y 200 Pa, rho 2300 kg/m3, mu_p 200 Pa s) in cells of 5 mm keeps its volume to
    round-off and comes to rest within three cells short of its closed form, never past it."""
    rho_g, tau, mu, dx = 2300.0 * 9.81, 200.0, 200.0, 0.005
    k = tau / rho_g
    for axisymmetric in (False, True):
        h = [0.1] * 40 + [0.0] * 160
        start = amount(h, dx, axisymmetric)
        for _ in range(60):
            h, u_max = step(h, dx, rho_g, tau, mu, 1.0, axisymmetric)
            if u_max < 1e-4:
                break
        end, closed = front(h, dx), rest_front(h, dx, k, axisymmetric)
        drift = abs(amount(h, dx, axisymmetric) / start - 1.0)
        name = "axisymmetric" if axisymmetric else "plane"
        print(f"{name}: front {end:.3f} m, closed form {closed:.4f} m, surface speed "
              f"{1000 * u_max:.3g} mm/s, volume drift {drift:.1e}")
        if drift > 1e-12 or u_max >= 1e-4 or not closed - 3 * dx <= end <= closed + dx:
            sys.exit(f"heap_lubrication self-test failed ({name})")


def main():
    if sys.argv[1:] == ["--self-test"]:
        self_test()
        return
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("--from-s", type=float, default=10.0)
    ap.add_argument("--every-s", type=float, default=10.0)
    ap.add_argument("--refine", type=int, default=2, help="model cells per spacing")
    ap.add_argument("--until-s", type=float, default=None,
                    help="carry the model on to this time (default: the run's end)")
    ap.add_argument("--rest-m-s", type=float, default=1e-4,
                    help="the model is at rest once its largest surface speed is below this")
    a = ap.parse_args()
    manifest, clouds, rows = clouds_and_rows(a.run)
    fluid = manifest["fluid"]
    scene = manifest["scene"]
    if manifest["dimension"] == 2 and scene["kind"] == "column_collapse":
        axisymmetric, copies, metric, name = False, 1, "heap_length_m", "heap length"
    elif manifest["dimension"] == 3 and scene["kind"] == "slump":
        copies = 4 if scene.get("quarter_domain", False) else 1
        axisymmetric, metric, name = True, "spread_radius_mean_m", "spread radius"
    else:
        sys.exit("heap_lubrication: a 2D column_collapse or a 3D slump run is needed")
    tau = fluid["yield_stress_pa"]
    mu = fluid["plastic_viscosity_pa_s"]
    t0, pc = min(clouds, key=lambda c: abs(c[0] - a.from_s))
    l0 = manifest["spacing_m"]
    # Model cells of l0 / refine (the front moves in whole cells), room to spread behind.
    dx = l0 / a.refine
    h = [v for v in surface(pc, l0, axisymmetric, copies) for _ in range(a.refine)]
    h += [0.0] * len(h)
    rho_g = fluid["density_kg_m3"] * manifest["gravity_m_s2"]
    runs_front = [(t, d.metrics[metric]) for t, d in rows]
    _, f0 = min(runs_front, key=lambda r: abs(r[0] - t0))
    print(f"# surface at t = {t0:.3f} s: {sum(v > 0 for v in h)} cells of {dx} m, "
          f"run's {name} {f0:.4f} m")
    print(f"| t (s) | run: {name} (m) | run: gain (mm) | thin layer: gain (mm) | thin layer: "
          "surface speed (mm/s) |")
    print("|---|---|---|---|---|")
    base = front(h, dx)
    t = t0
    run_end = runs_front[-1][0]
    until = run_end if a.until_s is None else a.until_s
    rest_s = None
    while t + a.every_s <= until + 0.5 * a.every_s:
        h, u_max = step(h, dx, rho_g, tau, mu, a.every_s, axisymmetric)
        t += a.every_s
        if t <= run_end + 0.5 * a.every_s:
            _, f = min(runs_front, key=lambda r: abs(r[0] - t))
            run = f"{f:.4f} | {1000 * (f - f0):.1f}"
        else:
            run = " | "
        print(f"| {t:.1f} | {run} | {1000 * (front(h, dx) - base):.1f} | {1000 * u_max:.3g} |")
        if u_max < a.rest_m_s:
            rest_s = t
            break
    print(f"# thin layer at rest (surface speed < {1000 * a.rest_m_s:g} mm/s): "
          + (f"by {rest_s:.1f} s" if rest_s is not None else f"not by {t:.1f} s"))
    k = tau / rho_g
    print(f"# thin layer's front at {t:.1f} s: {front(h, dx):.4f} m (at {t0:.1f} s: {base:.4f} m); "
          f"closed-form rest front for its {'volume' if axisymmetric else 'area'}: "
          f"{rest_front(h, dx, k, axisymmetric):.4f} m")


if __name__ == "__main__":
    main()
