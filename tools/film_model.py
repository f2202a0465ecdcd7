#!/usr/bin/env python3
"""The MPS viscous Laplacian's steady film, row by row: which boundary makes it fast?

A Newtonian film of N rows (spacing l0) on a no-slip floor, free on top, driven along the
floor by a body force f, is the 1D problem mu u'' = -f with u(0) = 0 and u'(h) = 0, h = N l0:
u(y) = (f / mu) (h y - y^2 / 2). This solves the same problem with the discrete operator the
solver uses, reduced to rows: the MPS Laplacian (2 d / (lambda n0)) sum_j (u_j - u_i) w_ij
over the d-dimensional lattice's neighbours within the radius, w = r_e / r - 1, lambda and
n0 from the same lattice sums, every neighbour of a row at the same speed (a film uniform
along the floor). Two choices are varied:

- the floor: `linear`, the solver's mirror (`mps.wall_surface_no_slip`): a wall neighbour
  d_j behind the no-slip surface carries -u_i d_j / d_i, the line through the wall and i; or
  `quadratic`, the smooth continuation of the film's parabola (the linear mirror plus
  u'' d_j (d_j + d_i) / 2, u'' = -f / mu known here);
- the free surface: `cut`, the solver's (a neighbour missing above the surface adds
  nothing, the operator stays normalised by the full lattice's lambda n0); or `image`, each
  missing neighbour carries the speed of the row it mirrors onto across the surface
  h = N l0 (zero stress, u'(h) = 0).

It prints each row's speed over the closed form's. The linear mirror alone puts the row
over the floor at d_0 tau_w / mu, high by (f / mu) d_0^2 / 2 (docs/validation.md, "The
walls' pressure along a periodic slope"), and every row above carries that offset.

Usage: tools/film_model.py [--rows N] [--radius R ...] [--dimension D]
"""
import argparse
import itertools
import math


def row_weights(radius, dimension):
    """Per vertical offset c (in spacings), the summed weight of the lattice neighbours at
    that offset; and lambda (in spacings squared) and n0 of the full lattice."""
    reach = int(math.floor(radius))
    by_offset = {}
    second_moment = 0.0
    n0 = 0.0
    for offset in itertools.product(range(-reach, reach + 1), repeat=dimension):
        r = math.sqrt(sum(o * o for o in offset))
        if r == 0.0 or r > radius:
            continue
        w = radius / r - 1.0
        by_offset[offset[-1]] = by_offset.get(offset[-1], 0.0) + w
        second_moment += r * r * w
        n0 += w
    return by_offset, second_moment / n0, n0


def solve(matrix, rhs):
    """Gaussian elimination with partial pivoting (the systems are a few rows)."""
    n = len(rhs)
    a = [row[:] + [b] for row, b in zip(matrix, rhs)]
    for col in range(n):
        pivot = max(range(col, n), key=lambda r: abs(a[r][col]))
        a[col], a[pivot] = a[pivot], a[col]
        for r in range(col + 1, n):
            factor = a[r][col] / a[col][col]
            for k in range(col, n + 1):
                a[r][k] -= factor * a[col][k]
    x = [0.0] * n
    for r in range(n - 1, -1, -1):
        x[r] = (a[r][n] - sum(a[r][k] * x[k] for k in range(r + 1, n))) / a[r][r]
    return x


def film(rows, radius, dimension, wall, surface):
    """Each row's steady speed over the closed form's (any f, mu, l0: the ratio is
    independent of them; here f / mu = 1, l0 = 1)."""
    by_offset, lam, n0 = row_weights(radius, dimension)
    scale = 2.0 * dimension / (lam * n0)
    matrix = [[0.0] * rows for _ in range(rows)]
    rhs = [-1.0] * rows
    for k in range(rows):
        d_k = k + 0.5
        for c, w in by_offset.items():
            m = k + c
            if c == 0:
                continue
            if 0 <= m < rows:
                matrix[k][m] += scale * w
                matrix[k][k] -= scale * w
            elif m < 0:
                d_j = -(m + 0.5)
                matrix[k][k] += scale * w * (-d_j / d_k - 1.0)
                if wall == "quadratic":
                    # u_j gains u'' d_j (d_j + d_k) / 2 with u'' = -1: a known term.
                    rhs[k] -= scale * w * (-1.0) * d_j * (d_j + d_k) / 2.0
            elif surface == "image":
                mirrored = 2 * rows - 1 - m
                if 0 <= mirrored < rows:
                    matrix[k][mirrored] += scale * w
                    matrix[k][k] -= scale * w
    speeds = solve(matrix, rhs)
    h = float(rows)
    closed = [(h * (k + 0.5) - (k + 0.5) ** 2 / 2.0) for k in range(rows)]
    return [s / e for s, e in zip(speeds, closed)]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=4)
    parser.add_argument("--radius", type=float, nargs="+", default=[2.1, 3.1])
    parser.add_argument("--dimension", type=int, default=3, choices=[2, 3])
    args = parser.parse_args()
    print(f"# {args.rows} rows, {args.dimension}D lattice; each row's speed / closed form, floor first")
    for radius in args.radius:
        for wall in ("linear", "quadratic"):
            for surface in ("cut", "image"):
                ratios = film(args.rows, radius, args.dimension, wall, surface)
                print(
                    f"radius {radius}  floor {wall:9s}  surface {surface:5s}  "
                    + " ".join(f"{r:.4f}" for r in ratios)
                )


if __name__ == "__main__":
    main()
