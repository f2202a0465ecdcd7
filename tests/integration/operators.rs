//! MPS operators on a regular lattice against exact values (docs/design.md section 3).
use crate::common;
use mps_runner::mps::Vector;
use mps_runner::mps::grid::Neighbours;
use mps_runner::mps::kernel::{RefValues, weight};
use mps_runner::mps::multigrid::Multigrid;
use mps_runner::mps::operators::{gradient, laplacian, number_density};
use mps_runner::mps::pressure::{Preconditioner, solve_pcg, solve_pcg_many};
use mps_runner::mps::sparse::CsrMatrix;

/// Square/cubic lattice of side `side` cells with spacing l0; returns positions and the index
/// of a particle in the middle.
fn lattice<const D: usize>(side: usize, l0: f64) -> (Vec<Vector<D>>, usize) {
    let mut pos = Vec::new();
    for flat in 0..side.pow(D as u32) {
        let mut rest = flat;
        let p = Vector::<D>::from_fn(|_, _| {
            let k = rest % side;
            rest /= side;
            k as f64 * l0 + 0.37 // offset: the operators must not depend on the origin
        });
        pos.push(p);
    }
    let mid = (0..D).fold(0, |acc, _| acc * side + side / 2);
    (pos, mid)
}

#[test]
fn n0_and_lambda_match_hand_sums_in_2d() {
    let l0 = 0.01;
    let refs = RefValues::on_lattice::<2>(l0, 2.1 * l0, 3.1 * l0);
    // re = 2.1: neighbours at 1 (x4), sqrt 2 (x4), 2 (x4) spacings.
    let n0 = 4.0 * (2.1 - 1.0) + 4.0 * (2.1 / 2f64.sqrt() - 1.0) + 4.0 * (2.1 / 2.0 - 1.0);
    // A 12-term sum of values below 1.1: round-off of order 1e-15.
    assert!((refs.n0 - n0).abs() < 1e-12, "{} vs {}", refs.n0, n0);
    // re = 3.1 adds sqrt5 (x8), sqrt8 (x4), 3 (x4).
    let shells: [(f64, f64); 6] = [
        (1.0, 4.0),
        (2f64.sqrt(), 4.0),
        (2.0, 4.0),
        (5f64.sqrt(), 8.0),
        (8f64.sqrt(), 4.0),
        (3.0, 4.0),
    ];
    let (mut sw, mut swr2) = (0.0, 0.0);
    for (r, m) in shells {
        let w = 3.1 / r - 1.0;
        sw += m * w;
        swr2 += m * w * (r * l0) * (r * l0);
    }
    // 24-term sums: round-off of order 1e-14 on n0 (about 19) and 1e-19 m^2 on lambda
    // (about 2.5e-4 m^2).
    assert!((refs.n0_lap - sw).abs() < 1e-12);
    assert!((refs.lambda_m2 - swr2 / sw).abs() < 1e-18);
    assert_eq!(weight(3.1 * l0, 3.1 * l0), 0.0, "w vanishes at re");
}

#[test]
fn n0_and_lambda_match_hand_sums_in_3d() {
    let l0 = 0.01;
    let refs = RefValues::on_lattice::<3>(l0, 2.1 * l0, 3.1 * l0);
    // re = 2.1: shells at 1 (x6), sqrt 2 (x12), sqrt 3 (x8) and 2 (x6) spacings.
    let n0 = 6.0 * (2.1 - 1.0)
        + 12.0 * (2.1 / 2f64.sqrt() - 1.0)
        + 8.0 * (2.1 / 3f64.sqrt() - 1.0)
        + 6.0 * (2.1 / 2.0 - 1.0);
    // A 32-term sum of values below 1.1: round-off of order 1e-14.
    assert!((refs.n0 - n0).abs() < 1e-12, "{} vs {}", refs.n0, n0);
    // re = 3.1 adds sqrt 5 (x24), sqrt 6 (x24), sqrt 8 (x12) and 3 (x30: (3,0,0) and
    // (2,2,1)); sqrt 10 = 3.16 lies outside.
    let shells: [(f64, f64); 8] = [
        (1.0, 6.0),
        (2f64.sqrt(), 12.0),
        (3f64.sqrt(), 8.0),
        (2.0, 6.0),
        (5f64.sqrt(), 24.0),
        (6f64.sqrt(), 24.0),
        (8f64.sqrt(), 12.0),
        (3.0, 30.0),
    ];
    let (mut sw, mut swr2) = (0.0, 0.0);
    for (r, m) in shells {
        let w = 3.1 / r - 1.0;
        sw += m * w;
        swr2 += m * w * (r * l0) * (r * l0);
    }
    // 122-term sums: round-off of order 1e-13 on n0 (about 40) and 1e-19 m^2 on lambda.
    assert!((refs.n0_lap - sw).abs() < 1e-12, "{} vs {sw}", refs.n0_lap);
    assert!((refs.lambda_m2 - swr2 / sw).abs() < 1e-18);
}

fn check_operators<const D: usize>() {
    let l0 = 0.02;
    let (pos, mid) = lattice::<D>(9, l0);
    let refs = RefValues::on_lattice::<D>(l0, 2.1 * l0, 3.1 * l0);
    let nb = Neighbours::build(&pos, refs.radius_lap_m);

    // Number density of an interior particle equals n0.
    let n = number_density(&pos, &nb, mid, refs.radius_n_m, |_| true);
    // The same sum as n0 from displacements that differ by the rounding of positions away
    // from the origin: relative round-off of order 1e-15.
    assert!(
        (n - refs.n0).abs() < 1e-12 * refs.n0,
        "n = {n}, n0 = {}",
        refs.n0
    );

    // Gradient of a linear field a . x + c is exact on a full lattice.
    let a = Vector::<D>::from_fn(|k, _| 1.5 - 0.7 * k as f64);
    let phi = |p: &Vector<D>| a.dot(p) + 3.0;
    let g = gradient(&pos, &nb, mid, refs.radius_n_m, refs.n0, |j| {
        Some(phi(&pos[j]) - phi(&pos[mid]))
    });
    // Exact for a linear field on a full lattice; differences of field values of order 1
    // divided by distances of order l0 leave round-off of order 1e-13.
    assert!((g - a).norm() < 1e-10, "gradient {g:?} vs {a:?}");

    // Laplacian of a quadratic |x|^2 (plus linear terms) is exactly 2D.
    let q = |p: &Vector<D>| p.norm_squared() + a.dot(p);
    let lap = laplacian::<D, 1>(
        &pos,
        &nb,
        mid,
        refs.radius_lap_m,
        refs.n0_lap,
        refs.lambda_m2,
        |j| Some(nalgebra::SVector::<f64, 1>::new(q(&pos[j]) - q(&pos[mid]))),
    );
    // Exact on a full lattice by the definition of lambda; differences of |x|^2 of order 0.5
    // divided by lambda (about 1e-3 m^2) leave round-off of order 1e-13.
    assert!(
        (lap[0] - 2.0 * D as f64).abs() < 1e-9,
        "laplacian {} vs {}",
        lap[0],
        2 * D
    );

    // Neighbour lists hold exactly the particles within the cutoff, none twice, not i itself.
    for i in 0..pos.len() {
        let brute: Vec<u32> = (0..pos.len())
            .filter(|&j| j != i && (pos[j] - pos[i]).norm() < refs.radius_lap_m)
            .map(|j| j as u32)
            .collect();
        let mut got = nb.of(i).to_vec();
        got.sort();
        assert_eq!(got, brute, "neighbours of {i}");
    }
}

#[test]
fn operators_exact_on_lattice_2d() {
    check_operators::<2>();
}

#[test]
fn operators_exact_on_lattice_3d() {
    check_operators::<3>();
}

/// 5-point Poisson matrix on an m x m grid with Dirichlet borders (SPD).
fn poisson(m: usize) -> CsrMatrix {
    let mut a = CsrMatrix {
        row_offsets: vec![0],
        ..Default::default()
    };
    for y in 0..m {
        for x in 0..m {
            a.diagonal.push(4.0);
            let mut cols = Vec::new();
            if y > 0 {
                cols.push((y - 1) * m + x)
            }
            if x > 0 {
                cols.push(y * m + x - 1)
            }
            if x + 1 < m {
                cols.push(y * m + x + 1)
            }
            if y + 1 < m {
                cols.push((y + 1) * m + x)
            }
            for c in cols {
                a.columns.push(c as u32);
                a.values.push(-1.0);
            }
            a.row_offsets.push(a.columns.len());
        }
    }
    a
}

#[test]
fn pcg_meets_its_residual_tolerance() {
    let m = 40;
    let a = poisson(m);
    let x_true: Vec<f64> = (0..m * m)
        .map(|i| ((i * 37 % 101) as f64 / 101.0) - 0.3)
        .collect();
    let b = product(&a, &x_true);
    let mut x = vec![0.0; m * m];
    let tol = 1e-10;
    let report = solve_pcg(&a, &b, &mut x, tol, 10_000, Preconditioner::Jacobi);
    assert!(report.converged, "{report:?}");
    // The true residual (not the recursively updated one) meets the tolerance.
    let ax = product(&a, &x);
    let r: f64 = ax
        .iter()
        .zip(&b)
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f64>()
        .sqrt();
    let bn: f64 = b.iter().map(|v| v * v).sum::<f64>().sqrt();
    // CG stops on its recursive residual; the true one drifts from it by round-off, far less
    // than a factor 10 at this size.
    assert!(r / bn < 10.0 * tol, "true residual {}", r / bn);
    let err = x
        .iter()
        .zip(&x_true)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max);
    // Error <= condition number (about 680 for this 5-point Poisson matrix) times the
    // relative residual (1e-9): 7e-7. MEASURED: 1.1e-9.
    assert!(err < 1e-6, "max error {err}");
    // An iteration cap below what the system needs is reported as not converged.
    x.iter_mut().for_each(|v| *v = 0.0);
    let capped = solve_pcg(&a, &b, &mut x, tol, 5, Preconditioner::Jacobi);
    assert!(!capped.converged && capped.iterations == 5);
}

/// A Poisson test problem: the matrix, its rows' lattice cells, a known solution and its
/// right-hand side.
type PoissonProblem = (CsrMatrix, Vec<[i64; 3]>, Vec<f64>, Vec<[f64; 1]>);

/// The m x m Poisson matrix with its cells, a known solution and its right-hand side.
fn poisson_problem(m: usize) -> PoissonProblem {
    let a = poisson(m);
    let n = m * m;
    let cells: Vec<[i64; 3]> = (0..n)
        .map(|i| [(i % m) as i64, (i / m) as i64, 0])
        .collect();
    let x_true: Vec<f64> = (0..n)
        .map(|i| ((i * 37 % 101) as f64 / 101.0) - 0.3)
        .collect();
    let b: Vec<[f64; 1]> = product(&a, &x_true).into_iter().map(|v| [v]).collect();
    (a, cells, x_true, b)
}

fn product(a: &CsrMatrix, x: &[f64]) -> Vec<f64> {
    let x: Vec<[f64; 1]> = x.iter().map(|&v| [v]).collect();
    let mut y = vec![[0.0]; x.len()];
    a.multiply(&x, &mut y);
    y.iter().map(|v| v[0]).collect()
}

#[test]
fn side_by_side_solves_give_the_bits_of_single_solves() {
    // Three right-hand sides, one of them zero, solved together and one by one (the viscous
    // stage solves the velocity components together).
    let m = 30;
    let a = poisson(m);
    let n = m * m;
    let b: Vec<[f64; 3]> = (0..n)
        .map(|i| [((i * 37 % 101) as f64) - 50.0, 0.0, (i % 7) as f64 * 1e-3])
        .collect();
    let guess: Vec<[f64; 3]> = (0..n).map(|i| [0.0, 1.0, (i % 3) as f64]).collect();
    let mut together = guess.clone();
    let reports = solve_pcg_many(&a, &b, &mut together, 1e-10, 10_000, Preconditioner::Jacobi);
    for axis in 0..3 {
        let b_axis: Vec<f64> = b.iter().map(|v| v[axis]).collect();
        let mut alone: Vec<f64> = guess.iter().map(|v| v[axis]).collect();
        let report = solve_pcg(
            &a,
            &b_axis,
            &mut alone,
            1e-10,
            10_000,
            Preconditioner::Jacobi,
        );
        assert_eq!(report, reports[axis], "axis {axis}");
        for i in 0..n {
            assert_eq!(
                alone[i].to_bits(),
                together[i][axis].to_bits(),
                "axis {axis} row {i}"
            );
        }
    }
    assert_eq!(reports[1].iterations, 0);
    assert!(reports[0].iterations > 10 && reports[2].iterations > 10);
    assert_ne!(reports[0].iterations, reports[2].iterations);
}

#[test]
fn multigrid_preconditioner_cuts_iterations_and_keeps_bits_across_threads() {
    // 5-point Poisson on a 100 x 100 grid: Jacobi-PCG needs O(m) iterations, the aggregation
    // multigrid cycle a number nearly independent of m.
    let m = 100;
    let (a, cells, _, b) = poisson_problem(m);
    let n = m * m;
    let tol = 1e-10;
    let solve = |threads: usize, multigrid: bool| {
        common::on_threads(threads, || {
            let mg = Multigrid::new(&a, &cells, 1.0, false);
            let pc = if multigrid {
                Preconditioner::Multigrid(&mg)
            } else {
                Preconditioner::Jacobi
            };
            let mut x = vec![[0.0]; n];
            let [report] = solve_pcg_many(&a, &b, &mut x, tol, 10_000, pc);
            (report, x, mg.depth())
        })
    };
    let (jacobi, _, _) = solve(2, false);
    let (mg1, x1, depth) = solve(1, true);
    let (mg2, x2, _) = solve(2, true);
    assert!(jacobi.converged && mg1.converged, "{jacobi:?} {mg1:?}");
    assert!(depth >= 4, "levels: {depth}");
    // Jacobi-PCG needs O(size) iterations, multigrid about as many at any size: a factor 5
    // leaves room. MEASURED: 19 against 288.
    assert!(
        mg1.iterations * 5 < jacobi.iterations,
        "multigrid {} vs Jacobi {} iterations",
        mg1.iterations,
        jacobi.iterations
    );
    assert_eq!(mg1, mg2);
    assert!(same_bits(&x1, &x2));
    // The true residual meets the tolerance (against the recursive one: a factor 10).
    let r = true_relative_residual(&a, &x1, &b);
    assert!(r < 10.0 * tol, "true residual {r}");
}

/// |b - A x| / |b|, with A x formed anew.
fn true_relative_residual(a: &CsrMatrix, x: &[[f64; 1]], b: &[[f64; 1]]) -> f64 {
    let x: Vec<f64> = x.iter().map(|v| v[0]).collect();
    let r: f64 = product(a, &x)
        .iter()
        .zip(b)
        .map(|(p, q)| (p - q[0]).powi(2))
        .sum::<f64>()
        .sqrt();
    r / b.iter().map(|v| v[0] * v[0]).sum::<f64>().sqrt()
}

/// Whether two solutions are the same bits, entry by entry.
fn same_bits(x: &[[f64; 1]], y: &[[f64; 1]]) -> bool {
    x.len() == y.len()
        && x.iter()
            .zip(y)
            .all(|(p, q)| p[0].to_bits() == q[0].to_bits())
}

#[test]
fn inactive_particles_are_nobodys_neighbours_and_others_need_no_list() {
    // Ghosts (fluid that left the domain) take part in nothing; particles that are not
    // centres (dummy layers) are neighbours but have no list of their own.
    let l0 = 0.01;
    let pos: Vec<Vector<2>> = (0..100)
        .map(|k| Vector::<2>::new((k % 10) as f64 * l0, (k / 10) as f64 * l0))
        .collect();
    let (ghost, dummy) = (44, 45);
    let nb = Neighbours::build_centres(&pos, 3.1 * l0, |i| i != ghost, |i| i != dummy);
    for i in 0..pos.len() {
        assert!(!nb.of(i).contains(&(ghost as u32)), "{i} lists the ghost");
    }
    assert!(nb.of(ghost).is_empty() && nb.of(dummy).is_empty());
    assert!(nb.of(46).contains(&(dummy as u32)));
    assert!(!nb.of(43).is_empty());
}

#[test]
fn multigrid_over_correction_cuts_iterations_and_their_growth_with_size() {
    // Plain aggregation's piecewise-constant prolongation under-shoots smooth errors: its
    // iteration count grows with the grid. Scaling each coarse correction by 1.5 makes up for
    // most of it (docs/performance.md, "Multigrid over-correction"). 5-point Poisson, m x m.
    let iterations = |m: usize, over_correction: f64| {
        let (a, cells, x_true, b) = poisson_problem(m);
        let mg = Multigrid::new(&a, &cells, over_correction, false);
        let mut x = vec![[0.0]; m * m];
        let [report] = solve_pcg_many(
            &a,
            &b,
            &mut x,
            1e-10,
            10_000,
            Preconditioner::Multigrid(&mg),
        );
        assert!(report.converged, "{report:?}");
        // The over-corrected cycle is still a symmetric positive definite preconditioner:
        // plain CG reaches the true solution.
        let err = x
            .iter()
            .zip(&x_true)
            .map(|(p, q)| (p[0] - q).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-6, "max error {err}");
        report.iterations
    };
    let (plain_small, plain_large) = (iterations(32, 1.0), iterations(256, 1.0));
    let (over_small, over_large) = (iterations(32, 1.5), iterations(256, 1.5));
    eprintln!("plain {plain_small} -> {plain_large}, over-corrected {over_small} -> {over_large}");
    assert!(over_large < plain_large, "{over_large} vs {plain_large}");
    assert!(
        over_large - over_small < plain_large - plain_small,
        "growth {over_small}->{over_large} vs {plain_small}->{plain_large}"
    );
}

#[test]
fn a_single_precision_smoother_keeps_the_iterations_and_the_true_residual() {
    // The 5-point Poisson matrix with its entries scaled by 0.1 and varied smoothly, so that no
    // entry is exact in f32 (docs/performance.md, "A single-precision smoother"). The cycle
    // whose finest smoothing reads the f32 copy must keep CG's iterations within one of the
    // f64 cycle's, meet the tolerance on the f64 matrix, and give the same bits on 1 and 2
    // threads.
    let m = 128;
    let (mut a, cells, x_true, _) = poisson_problem(m);
    for i in 0..a.rows() {
        for k in a.row_offsets[i]..a.row_offsets[i + 1] {
            let j = a.columns[k] as usize;
            // Symmetric in (i, j): the weight of the pair, from both ends' indices.
            let w = 1.0 + 0.3 * (((i + j) % 17) as f64 / 17.0);
            a.values[k] *= 0.1 * w;
        }
    }
    // Weakly diagonally dominant rows, as the MPS Laplacian's are.
    for i in 0..a.rows() {
        let off: f64 = (a.row_offsets[i]..a.row_offsets[i + 1])
            .map(|k| a.values[k].abs())
            .sum();
        a.diagonal[i] = off + 1e-3;
    }
    assert!(
        a.values.iter().any(|&v| f64::from(v as f32) != v),
        "some entry must differ in f32"
    );
    let b: Vec<[f64; 1]> = product(&a, &x_true).into_iter().map(|v| [v]).collect();
    let tol = 1e-10;
    let solve = |threads: usize, single: bool| {
        common::on_threads(threads, || {
            let mg = Multigrid::new(&a, &cells, 1.5, single);
            let mut x = vec![[0.0]; m * m];
            let [report] =
                solve_pcg_many(&a, &b, &mut x, tol, 10_000, Preconditioner::Multigrid(&mg));
            (report, x)
        })
    };
    let (double, x_double) = solve(2, false);
    let (single1, x1) = solve(1, true);
    let (single2, x2) = solve(2, true);
    assert!(
        double.converged && single1.converged,
        "{double:?} {single1:?}"
    );
    eprintln!(
        "iterations: f64 smoother {}, f32 smoother {}",
        double.iterations, single1.iterations
    );
    assert!(
        single1.iterations <= double.iterations + 1,
        "f32 smoother {} vs f64 {} iterations",
        single1.iterations,
        double.iterations
    );
    // Another preconditioner: other bits, not the f64 path by mistake.
    assert!(!same_bits(&x1, &x_double));
    assert_eq!(single1, single2);
    assert!(same_bits(&x1, &x2));
    // CG's own product is f64: the true residual on A meets the tolerance.
    let r = true_relative_residual(&a, &x1, &b);
    assert!(r < 10.0 * tol, "true residual {r}");
}
