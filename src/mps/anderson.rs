//! Anderson acceleration of a fixed-point iteration s -> G(s) (Anderson 1965; Walker & Ni
//! 2011, over the last `depth` differences), with a plain safeguard: a residual that grows
//! clears the history, and the next step is the plain one.
//!
//! Given the last input s_k, its image g_k = G(s_k) and residual f_k = g_k - s_k, and the
//! differences of the earlier residuals and images (columns of dF and dG), the next input is
//! g_k - dG c with c = argmin |f_k - dF c| (normal equations, a tiny m x m system). An
//! auxiliary vector that the map also produces (e.g. the velocity a step solved for) is mixed
//! with the same c: that is a good start for the next evaluation. Every dot product is an
//! order-fixed sum ([`dot`]), so the accelerated iterates are the same on any thread count.
use super::dense::DenseCholesky;
use super::reduce::dot;
use std::collections::VecDeque;

/// Relative Tikhonov term on the normal equations' diagonal: keeps them solvable when two
/// residual differences are nearly parallel.
const REGULARISATION: f64 = 1e-10;

pub(crate) struct Anderson {
    depth: usize,
    /// The last evaluation.
    last: Option<Evaluation>,
    /// Differences of residuals, images and auxiliary outputs, oldest first.
    history: VecDeque<(Vec<f64>, Vec<f64>, Vec<f64>)>,
    /// The residual differences' dot products, row a column b for history entries a and b
    /// (each computed once, when its newer entry came).
    gram: VecDeque<VecDeque<f64>>,
}

/// One evaluation of the map: its image, residual (image - input), auxiliary output and
/// |residual|^2.
struct Evaluation {
    image: Vec<f64>,
    residual: Vec<f64>,
    aux: Vec<f64>,
    norm2: f64,
}

impl Anderson {
    pub(crate) fn new(depth: usize) -> Self {
        Self {
            depth,
            last: None,
            history: VecDeque::new(),
            gram: VecDeque::new(),
        }
    }

    /// Forgets every earlier iterate (the map changed, e.g. a new penalty).
    pub(crate) fn restart(&mut self) {
        self.last = None;
        self.forget();
    }

    fn forget(&mut self) {
        self.history.clear();
        self.gram.clear();
    }

    /// The next input after evaluating the map at `input` (image `image`, auxiliary output
    /// `aux`): returns (next input, next auxiliary guess). The plain step (`image`, `aux`)
    /// when there is no usable history.
    pub(crate) fn next(
        &mut self,
        input: &[f64],
        image: &[f64],
        aux: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let residual: Vec<f64> = image.iter().zip(input).map(|(g, s)| g - s).collect();
        let norm2 = dot(&residual, &residual);
        if let Some(last) = self.last.take() {
            if norm2 > last.norm2 {
                self.forget();
            } else {
                let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x - y).collect();
                let df: Vec<f64> = diff(&residual, &last.residual);
                let mut row: VecDeque<f64> =
                    self.history.iter().map(|(fb, _, _)| dot(&df, fb)).collect();
                row.push_back(dot(&df, &df));
                for (earlier, &v) in self.gram.iter_mut().zip(&row) {
                    earlier.push_back(v);
                }
                self.gram.push_back(row);
                self.history
                    .push_back((df, diff(image, &last.image), diff(aux, &last.aux)));
                if self.history.len() > self.depth {
                    self.history.pop_front();
                    self.gram.pop_front();
                    for row in &mut self.gram {
                        row.pop_front();
                    }
                }
            }
        }
        self.last = Some(Evaluation {
            image: image.to_vec(),
            residual: residual.clone(),
            aux: aux.to_vec(),
            norm2,
        });
        let m = self.history.len();
        if m == 0 {
            return (image.to_vec(), aux.to_vec());
        }
        let mut gram: Vec<f64> = self.gram.iter().flatten().copied().collect();
        let rhs: Vec<f64> = self
            .history
            .iter()
            .map(|(fa, _, _)| dot(fa, &residual))
            .collect();
        let scale = (0..m).map(|a| gram[a * m + a]).fold(0.0, f64::max);
        for a in 0..m {
            gram[a * m + a] += REGULARISATION * scale;
        }
        let Some(normal) = DenseCholesky::factor(gram, m, false) else {
            self.forget();
            return (image.to_vec(), aux.to_vec());
        };
        let mut c = vec![0.0; m];
        normal.solve(&rhs, &mut c);
        let mut next = image.to_vec();
        let mut guess = aux.to_vec();
        for (ca, (_, dg, da)) in c.iter().zip(&self.history) {
            next.iter_mut().zip(dg).for_each(|(x, d)| *x -= ca * d);
            guess.iter_mut().zip(da).for_each(|(x, d)| *x -= ca * d);
        }
        (next, guess)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear contraction s -> M s + c converges in far fewer accelerated steps than plain
    /// ones (Anderson on a linear map is GMRES-like).
    #[test]
    fn accelerates_a_slow_linear_contraction() {
        let n = 40;
        let map = |s: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let rate = 0.5 + 0.49 * (i as f64 / (n - 1) as f64);
                    rate * s[i] + 1.0
                })
                .collect()
        };
        let exact: Vec<f64> = (0..n)
            .map(|i| 1.0 / (1.0 - (0.5 + 0.49 * (i as f64 / (n - 1) as f64))))
            .collect();
        let error = |s: &[f64]| {
            s.iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
        };
        let steps_to = |depth: usize| {
            let mut aa = Anderson::new(depth);
            let mut s = vec![0.0; n];
            for k in 0..5000 {
                if error(&s) < 1e-8 {
                    return k;
                }
                let g = map(&s);
                s = if depth == 0 {
                    g
                } else {
                    aa.next(&s, &g, &[]).0
                };
            }
            5000
        };
        let plain = steps_to(0);
        let accelerated = steps_to(5);
        eprintln!("plain {plain}, accelerated {accelerated}");
        assert!(plain > 2000, "plain {plain}");
        assert!(
            accelerated * 5 < plain,
            "accelerated {accelerated}, plain {plain}"
        );
    }
}
