//! Conjugate gradients (Shewchuk 1994) on the weighted screened Poisson normal equations
//!   (α² W_g + D_xᵀ W_x D_x + D_yᵀ W_y D_y) I = α² W_g I^g + D_xᵀ W_x I^dx + D_yᵀ W_y I^dy,
//! matrix-free, with a Jacobi preconditioner. Weights are per residual row (IRLS).

use super::Channel;
use std::borrow::Cow;

pub struct WeightedProblem<'a> {
    pub c: &'a Channel<'a>,
    pub alpha: f64,
    /// Row weights (shared by the channels of one IRLS step, hence borrowed there).
    pub wg: Cow<'a, [f64]>,
    pub wx: Cow<'a, [f64]>,
    pub wy: Cow<'a, [f64]>,
}

impl<'a> WeightedProblem<'a> {
    pub fn unweighted(c: &'a Channel<'a>, alpha: f64) -> Self {
        let n = c.width * c.height;
        let ones = || Cow::Owned(vec![1.0; n]);
        WeightedProblem { c, alpha, wg: ones(), wx: ones(), wy: ones() }
    }

    fn apply(&self, v: &[f64], out: &mut [f64]) {
        let (w, h) = (self.c.width, self.c.height);
        let a2 = self.alpha * self.alpha;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let mut s = a2 * self.wg[i] * v[i];
                if x + 1 < w {
                    s += self.wx[i] * (v[i] - v[i + 1]);
                }
                if x > 0 {
                    s += self.wx[i - 1] * (v[i] - v[i - 1]);
                }
                if y + 1 < h {
                    s += self.wy[i] * (v[i] - v[i + w]);
                }
                if y > 0 {
                    s += self.wy[i - w] * (v[i] - v[i - w]);
                }
                out[i] = s;
            }
        }
    }

    fn diagonal(&self) -> Vec<f64> {
        let (w, h) = (self.c.width, self.c.height);
        let a2 = self.alpha * self.alpha;
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let mut d = a2 * self.wg[i];
                if x + 1 < w {
                    d += self.wx[i];
                }
                if x > 0 {
                    d += self.wx[i - 1];
                }
                if y + 1 < h {
                    d += self.wy[i];
                }
                if y > 0 {
                    d += self.wy[i - w];
                }
                d.max(1e-300)
            })
            .collect()
    }

    fn rhs(&self) -> Vec<f64> {
        let (w, h) = (self.c.width, self.c.height);
        let a2 = self.alpha * self.alpha;
        let c = self.c;
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let mut b = a2 * self.wg[i] * c.primal[i];
                if x + 1 < w {
                    b -= self.wx[i] * c.dx[i];
                }
                if x > 0 {
                    b += self.wx[i - 1] * c.dx[i - 1];
                }
                if y + 1 < h {
                    b -= self.wy[i] * c.dy[i];
                }
                if y > 0 {
                    b += self.wy[i - w] * c.dy[i - w];
                }
                b
            })
            .collect()
    }
}

/// Preconditioned CG from `x0`; stops after `iters` or when ‖r‖ ≤ tol·‖b‖.
/// Stops early, with the current iterate, once `stop()` is true (asked every iteration).
pub fn solve_cg(p: &WeightedProblem, x0: &[f64], iters: usize, tol: f64, stop: &(dyn Fn() -> bool + Sync)) -> Vec<f64> {
    let n = x0.len();
    let b = p.rhs();
    let dinv: Vec<f64> = p.diagonal().iter().map(|d| 1.0 / d).collect();
    let mut x = x0.to_vec();
    let mut ax = vec![0.0; n];
    p.apply(&x, &mut ax);
    let mut r: Vec<f64> = b.iter().zip(&ax).map(|(b, a)| b - a).collect();
    let bnorm = b.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
    let mut z: Vec<f64> = r.iter().zip(&dinv).map(|(r, d)| r * d).collect();
    let mut d = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let mut ad = vec![0.0; n];
    for _ in 0..iters {
        if stop() || r.iter().map(|v| v * v).sum::<f64>().sqrt() <= tol * bnorm {
            break;
        }
        p.apply(&d, &mut ad);
        let dad: f64 = d.iter().zip(&ad).map(|(a, b)| a * b).sum();
        if dad <= 0.0 {
            break;
        }
        let a = rz / dad;
        for i in 0..n {
            x[i] += a * d[i];
            r[i] -= a * ad[i];
            z[i] = r[i] * dinv[i];
        }
        let rz_new: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            d[i] = z[i] + beta * d[i];
        }
    }
    x
}
