//! Exact L2 screened Poisson solve by the 2-D DCT-II (Bhat et al. 2008): with the Neumann
//! boundary the operator α² + D_xᵀD_x + D_yᵀD_y is diagonal in the DCT-II basis, with
//! eigenvalues α² + (2 − 2cos(πu/W)) + (2 − 2cos(πv/H)).
//!
//! In f32, one channel at a time, each transform parallel over rows (the columns are
//! transposed into rows): two W·H planes of workspace besides the result, and every core
//! busy whatever the channel count.

use super::cg::{Problem, RowPlanar};
use rayon::prelude::*;
use rustdct::{DctPlanner, TransformType2And3};
use std::sync::Arc;

/// The right-hand side α²·I^g + D_xᵀ I^dx + D_yᵀ I^dy of channel `c` into `b` (row-major);
/// the gradient rows at the last column/row do not exist and are ignored.
fn rhs(p: &Problem, c: usize, b: &mut [f32]) {
    let (w, h) = (p.width(), p.height());
    let a2 = p.alpha * p.alpha;
    b.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let (g, gx, gy) = (p.primal.row(y, c), p.dx.row(y, c), p.dy.row(y, c));
        for x in 0..w {
            let mut v = a2 * g[x];
            if x + 1 < w {
                v -= gx[x];
            }
            if x > 0 {
                v += gx[x - 1];
            }
            if y + 1 < h {
                v -= gy[x];
            }
            out[x] = v;
        }
        if y > 0 {
            for (o, &v) in out.iter_mut().zip(p.dy.row(y - 1, c)) {
                *o += v;
            }
        }
    });
}

/// Applies `t` (DCT-II, or DCT-III when `inverse`) to every row of length `n`, in parallel.
fn rows(data: &mut [f32], n: usize, t: &Arc<dyn TransformType2And3<f32>>, inverse: bool) {
    data.par_chunks_mut(n).for_each_init(
        || vec![0.0f32; t.get_scratch_len()],
        |scratch, row| {
            if inverse {
                t.process_dct3_with_scratch(row, scratch)
            } else {
                t.process_dct2_with_scratch(row, scratch)
            }
        },
    );
}

/// `dst` (h×w: the columns of `src` as rows) = the transpose of the w×h (row-major) `src`.
fn transpose(src: &[f32], w: usize, h: usize, dst: &mut [f32]) {
    const T: usize = 32;
    dst.par_chunks_mut(T * h).enumerate().for_each(|(blk, out)| {
        let x0 = blk * T;
        for y0 in (0..h).step_by(T) {
            for y in y0..(y0 + T).min(h) {
                let row = &src[y * w..(y + 1) * w];
                for (k, &v) in row[x0..(x0 + T).min(w)].iter().enumerate() {
                    out[k * h + y] = v;
                }
            }
        }
    });
}

/// The exact L2 minimiser of the three channels.
pub fn solve_l2(p: &Problem) -> RowPlanar {
    let (w, h) = (p.width(), p.height());
    let mut planner = DctPlanner::<f32>::new();
    let (along_x, along_y) = (planner.plan_dct2(w), planner.plan_dct2(h));
    let a2 = (p.alpha as f64).powi(2);
    let ex: Vec<f64> = (0..w).map(|u| 2.0 - 2.0 * (std::f64::consts::PI * u as f64 / w as f64).cos()).collect();
    let ey: Vec<f64> = (0..h).map(|v| 2.0 - 2.0 * (std::f64::consts::PI * v as f64 / h as f64).cos()).collect();
    // rustdct's DCT-III inverts its DCT-II up to a factor N/2 per dimension
    let scale = (2.0 / w as f64) * (2.0 / h as f64);
    let mut out = RowPlanar::zeros(w, h);
    let mut plane = vec![0.0f32; w * h];
    let mut cols = vec![0.0f32; w * h];
    for c in 0..3 {
        rhs(p, c, &mut plane);
        rows(&mut plane, w, &along_x, false);
        transpose(&plane, w, h, &mut cols);
        rows(&mut cols, h, &along_y, false);
        cols.par_chunks_mut(h).enumerate().for_each(|(u, col)| {
            for (v, b) in col.iter_mut().enumerate() {
                let lambda = a2 + ex[u] + ey[v];
                // λ = 0 only for the constant mode at α = 0, where the mean is undetermined: keep 0
                *b = if lambda > 0.0 { (*b as f64 * scale / lambda) as f32 } else { 0.0 };
            }
        });
        rows(&mut cols, h, &along_y, true);
        transpose(&cols, h, w, &mut plane);
        rows(&mut plane, w, &along_x, true);
        out.set_channel(c, &plane);
    }
    out
}
