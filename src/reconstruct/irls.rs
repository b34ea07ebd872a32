//! L1 reconstruction by iteratively reweighted least squares: start from the exact L2
//! solution, then weight each residual row by 1/(‖e‖_RGB + reg_k) (weights normalised to
//! mean 1 over all 3N rows together, reg_k = reg₀·decay^(k−1)) and re-solve by warm-started CG. RGB channels share
//! their weights, so an outlier in one channel is treated as an outlier in all.

use super::{solve_cg, solve_l2_dct, Channel, WeightedProblem};
use rayon::prelude::*;
use std::borrow::Cow;

#[derive(Clone, Debug)]
pub struct IrlsParams {
    pub outer_iterations: usize,
    pub cg_iterations: usize,
    pub reg0: f64,
    pub decay: f64,
}

impl Default for IrlsParams {
    fn default() -> Self {
        // The public GDPT code uses 20 × 50. Measured on GDPT and GDPSSMLT renders of the
        // Cornell box (96², 16 and 64 per pixel, relMSE against PT at 4096 spp, 2026-11-25):
        // 10 × 10 warm-started iterations land within ±1% of 20 × 50 (sometimes below it)
        // at 1/7 of the time; 5 × 20 is up to 13% worse, plain L2 up to 60% worse.
        IrlsParams { outer_iterations: 10, cg_iterations: 10, reg0: 0.05, decay: 0.5 }
    }
}

/// `stop` is asked between outer iterations and inside every CG iteration: when it turns true
/// (Esc), the current iterate — the L2 solution refined so far — is returned.
pub fn solve_l1(chans: &[Channel], alpha: f64, params: &IrlsParams, stop: &(dyn Fn() -> bool + Sync)) -> Vec<Vec<f64>> {
    let (w, h) = (chans[0].width, chans[0].height);
    let n = w * h;
    // channels are independent given the shared weights: solved in parallel
    let mut sol: Vec<Vec<f64>> = chans.par_iter().map(|c| solve_l2_dct(c, alpha)).collect();
    let mut reg = params.reg0;
    for _ in 0..params.outer_iterations {
        if stop() {
            break;
        }
        let weights: Vec<[f64; 3]> = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let (mut eg, mut ex, mut ey) = (0.0, 0.0, 0.0);
                for (c, s) in chans.iter().zip(&sol) {
                    eg += (alpha * (s[i] - c.primal[i])).powi(2);
                    if x + 1 < w {
                        ex += (s[i + 1] - s[i] - c.dx[i]).powi(2);
                    }
                    if y + 1 < h {
                        ey += (s[i + w] - s[i] - c.dy[i]).powi(2);
                    }
                }
                [1.0 / (eg.sqrt() + reg), 1.0 / (ex.sqrt() + reg), 1.0 / (ey.sqrt() + reg)]
            })
            .collect();
        // one normalisation over all 3N rows (as the reference implementation): the rows'
        // weights keep their ratios across the primal and the two gradient images
        // (the last column's x rows and the last row's y rows do not exist: left out)
        let rows = n + (w - 1) * h + w * (h - 1);
        let m = (0..n)
            .map(|i| {
                let w_i = &weights[i];
                w_i[0] + if i % w + 1 < w { w_i[1] } else { 0.0 } + if i / w + 1 < h { w_i[2] } else { 0.0 }
            })
            .sum::<f64>()
            / rows.max(1) as f64;
        let split = |k: usize| -> Vec<f64> { weights.iter().map(|w| if m > 0.0 { w[k] / m } else { 1.0 }).collect() };
        let (wg, wx, wy) = (split(0), split(1), split(2));
        sol.par_iter_mut().zip(chans.par_iter()).for_each(|(s, c)| {
            let p =
                WeightedProblem { c, alpha, wg: Cow::Borrowed(&wg), wx: Cow::Borrowed(&wx), wy: Cow::Borrowed(&wy) };
            *s = solve_cg(&p, s, params.cg_iterations, 1e-10, stop);
        });
        reg *= params.decay;
    }
    sol
}
