//! Exact L2 screened Poisson solve by the 2-D DCT-II (Bhat et al. 2008): with the Neumann
//! boundary the operator α² + D_xᵀD_x + D_yᵀD_y is diagonal in the DCT-II basis, with
//! eigenvalues α² + (2 − 2cos(πu/W)) + (2 − 2cos(πv/H)).

use super::{rhs, Channel};
use rustdct::DctPlanner;

/// Applies a 1-D transform to every row and then every column of a W×H image.
fn separable(data: &mut [f64], w: usize, h: usize, planner: &mut DctPlanner<f64>, inverse: bool) {
    let row = if inverse { planner.plan_dct3(w) } else { planner.plan_dct2(w) };
    for r in data.chunks_exact_mut(w) {
        if inverse {
            row.process_dct3(r)
        } else {
            row.process_dct2(r)
        }
    }
    let col = if inverse { planner.plan_dct3(h) } else { planner.plan_dct2(h) };
    let mut buf = vec![0.0; h];
    for x in 0..w {
        for y in 0..h {
            buf[y] = data[y * w + x];
        }
        if inverse {
            col.process_dct3(&mut buf)
        } else {
            col.process_dct2(&mut buf)
        }
        for y in 0..h {
            data[y * w + x] = buf[y];
        }
    }
}

pub fn solve_l2_dct(c: &Channel, alpha: f64) -> Vec<f64> {
    let (w, h) = (c.width, c.height);
    let mut b = rhs(c, alpha);
    let mut planner = DctPlanner::new();
    separable(&mut b, w, h, &mut planner, false);
    let a2 = alpha * alpha;
    let ex: Vec<f64> = (0..w).map(|u| 2.0 - 2.0 * (std::f64::consts::PI * u as f64 / w as f64).cos()).collect();
    let ey: Vec<f64> = (0..h).map(|v| 2.0 - 2.0 * (std::f64::consts::PI * v as f64 / h as f64).cos()).collect();
    for v in 0..h {
        for u in 0..w {
            let lambda = a2 + ex[u] + ey[v];
            // λ = 0 only for the constant mode at α = 0, where the mean is undetermined: keep 0.
            b[v * w + u] = if lambda > 0.0 { b[v * w + u] / lambda } else { 0.0 };
        }
    }
    separable(&mut b, w, h, &mut planner, true);
    // rustdct's DCT-III inverts its DCT-II up to a factor N/2 per dimension.
    let scale = (2.0 / w as f64) * (2.0 / h as f64);
    b.iter_mut().for_each(|v| *v *= scale);
    b
}
