//! Screened Poisson reconstruction of an image from a noisy primal I^g and its noisy
//! finite-difference gradients (docs/algorithm.md §5):
//!
//!   minimize  α²‖I − I^g‖² + ‖D_x I − I^dx‖² + ‖D_y I − I^dy‖²      (per channel)
//!
//! with forward differences and a free (Neumann) boundary: (D_x I)_i = I_{i+1} − I_i for
//! x < W−1, else 0. L2 is solved exactly by the DCT (Bhat et al. 2008); L1 by iteratively
//! reweighted least squares over conjugate gradients.

mod cg;
mod dct;
mod irls;

pub use cg::{Problem, RowPlanar, Weights};
pub use dct::solve_l2_dct;
pub use irls::{solve_l1, IrlsParams};

/// The inputs of a reconstruction: one channel each, row-major, rows from the top.
#[derive(Clone, Debug)]
pub struct Channel<'a> {
    pub width: usize,
    pub height: usize,
    pub primal: &'a [f64],
    pub dx: &'a [f64],
    pub dy: &'a [f64],
}

/// Forward differences with the Neumann boundary: returns (D_x I, D_y I).
pub fn gradients(img: &[f64], w: usize, h: usize) -> (Vec<f64>, Vec<f64>) {
    let mut dx = vec![0.0; w * h];
    let mut dy = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                dx[i] = img[i + 1] - img[i];
            }
            if y + 1 < h {
                dy[i] = img[i + w] - img[i];
            }
        }
    }
    (dx, dy)
}

/// Right-hand side of the normal equations: α²·I^g + D_xᵀ I^dx + D_yᵀ I^dy
/// (gradient rows at the last column/row do not exist and are ignored).
pub fn rhs(c: &Channel, alpha: f64) -> Vec<f64> {
    let (w, h) = (c.width, c.height);
    let a2 = alpha * alpha;
    let mut b = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut v = a2 * c.primal[i];
            if x + 1 < w {
                v -= c.dx[i];
            }
            if x > 0 {
                v += c.dx[i - 1];
            }
            if y + 1 < h {
                v -= c.dy[i];
            }
            if y > 0 {
                v += c.dy[i - w];
            }
            b[i] = v;
        }
    }
    b
}

/// Which solver and norm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Norm {
    L1,
    L2,
}

impl Norm {
    pub fn parse(s: &str) -> Option<Norm> {
        match s.to_ascii_lowercase().as_str() {
            "l1" => Some(Norm::L1),
            "l2" => Some(Norm::L2),
            _ => None,
        }
    }
}

/// The gradient-domain image: the reconstruction of (primal, dx, dy) plus the very-direct
/// light, clipped at 0 (the screened Poisson solve is unconstrained and rings slightly
/// negative in the dark). Returns (combined, primal + very direct). All RGB, row-major.
#[allow(clippy::too_many_arguments)]
pub fn gradient_domain_image(
    w: usize,
    h: usize,
    primal: &[f64],
    dx: &[f64],
    dy: &[f64],
    direct: &[f64],
    alpha: f64,
    norm: Norm,
    stop: &(dyn Fn() -> bool + Sync),
) -> (Vec<f64>, Vec<f64>) {
    let recon = reconstruct_rgb(w, h, primal, dx, dy, alpha, norm, stop);
    let combined = recon.iter().zip(direct).map(|(a, b)| (a + b).max(0.0)).collect();
    let primal_full = primal.iter().zip(direct).map(|(a, b)| a + b).collect();
    (combined, primal_full)
}

/// Reconstructs an RGB image from primal, dx, dy (each W·H·3 interleaved, f64); an L1 solve
/// returns early with its current iterate once `stop()` is true.
#[allow(clippy::too_many_arguments)]
pub fn reconstruct_rgb(
    w: usize,
    h: usize,
    primal: &[f64],
    dx: &[f64],
    dy: &[f64],
    alpha: f64,
    norm: Norm,
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<f64> {
    use rayon::prelude::*;
    let split = |v: &[f64], c: usize| -> Vec<f64> { v.par_chunks_exact(3).map(|p| p[c]).collect() };
    let chans: Vec<[Vec<f64>; 3]> =
        (0..3).into_par_iter().map(|c| [split(primal, c), split(dx, c), split(dy, c)]).collect();
    let views: Vec<Channel> =
        chans.iter().map(|[p, x, y]| Channel { width: w, height: h, primal: p, dx: x, dy: y }).collect();
    let out: Vec<Vec<f64>> = match norm {
        Norm::L2 => views.par_iter().map(|c| solve_l2_dct(c, alpha)).collect(),
        Norm::L1 => solve_l1(&views, alpha, &IrlsParams::default(), stop),
    };
    (0..w * h * 3).into_par_iter().with_min_len(1 << 14).map(|i| out[i % 3][i / 3]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    fn test_image(w: usize, h: usize) -> Vec<f64> {
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64, (i / w) as f64);
                (0.3 * x).sin() + 0.05 * y + if x > 7.0 && y < 5.0 { 2.0 } else { 0.0 }
            })
            .collect()
    }

    #[test]
    fn exact_gradients_reconstruct_the_image() {
        let (w, h) = (23, 17);
        let img = test_image(w, h);
        let (dx, dy) = gradients(&img, w, h);
        // Exact primal and gradients: the image itself is the minimiser for any α.
        let c = Channel { width: w, height: h, primal: &img, dx: &dx, dy: &dy };
        let l2 = solve_l2_dct(&c, 0.2);
        let l1 = solve_l1(&[c.clone(), c.clone(), c.clone()], 0.2, &IrlsParams::default(), &|| false);
        for i in 0..w * h {
            assert!((l2[i] - img[i]).abs() < 1e-9, "dct {} vs {}", l2[i], img[i]);
            assert!((l1[0][i] - img[i]).abs() < 1e-6, "l1 {} vs {}", l1[0][i], img[i]);
        }
        // A noisy primal with exact gradients: as α → 0 only the primal's mean survives.
        let mut s = IndependentSampler::new(1, 1);
        let noisy: Vec<f64> = img.iter().map(|v| v + (s.next_1d() as f64 - 0.5)).collect();
        let shift = img.iter().zip(&noisy).map(|(a, b)| a - b).sum::<f64>() / (w * h) as f64;
        let c = Channel { width: w, height: h, primal: &noisy, dx: &dx, dy: &dy };
        let a = 1e-3;
        let l2 = solve_l2_dct(&c, a);
        // deviation ≤ α²·|noise|/λ_min ≈ 1e-6·0.5/0.0187 ≈ 3e-5
        for i in 0..w * h {
            assert!((l2[i] - (img[i] - shift)).abs() < 1e-4, "dct {} vs {}", l2[i], img[i] - shift);
        }
    }

    /// CG (f32, three channels at once, banded) reaches the DCT's exact minimiser of the
    /// unweighted problem from a zero start, on images taller than one band, whatever the
    /// thread count (bit for bit).
    #[test]
    fn cg_reaches_the_exact_l2_minimiser_and_ignores_the_thread_count() {
        let (w, h) = (37, 2 * cg::BAND + 5);
        let img = test_image(w, h);
        let mut s = IndependentSampler::new(4, 1);
        let mut noisy = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| x + 0.3 * (s.next_1d() as f64 - 0.5)).collect() };
        let (dx, dy) = gradients(&img, w, h);
        let chans: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> =
            (0..3).map(|_| (noisy(&img), noisy(&dx), noisy(&dy))).collect();
        let views: Vec<Channel> =
            chans.iter().map(|(p, x, y)| Channel { width: w, height: h, primal: p, dx: x, dy: y }).collect();
        let planes = |k: usize| {
            let pick = |c: &Channel<'_>| -> Vec<f64> { [c.primal, c.dx, c.dy][k].to_vec() };
            let v: Vec<Vec<f64>> = views.iter().map(pick).collect();
            RowPlanar::from_planes([&v[0], &v[1], &v[2]], w, h)
        };
        let p = Problem { alpha: 0.2, primal: planes(0), dx: planes(1), dy: planes(2) };
        let solve = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let mut x = RowPlanar::zeros(w, h);
            pool.install(|| p.solve(&Weights::ones(w, h), &mut x, 400, 1e-7, &|| false));
            x
        };
        let (one, two) = (solve(1), solve(2));
        assert_eq!(one, two);
        for (c, view) in views.iter().enumerate() {
            let (exact, got) = (solve_l2_dct(view, 0.2), one.plane(c));
            for i in 0..w * h {
                assert!((got[i] - exact[i]).abs() < 1e-4, "cg {} vs dct {}", got[i], exact[i]);
            }
        }
    }

    /// An L1 solve asked to stop (Esc) returns its current iterate: the exact L2 solution when
    /// stopped before the first reweighting, something between L2 and the full L1 after a few
    /// CG steps; it asks once per outer iteration and once per CG step.
    #[test]
    fn a_stopped_l1_solve_returns_its_current_iterate() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let (w, h) = (24, 16);
        let img = test_image(w, h);
        let (mut dx, dy) = gradients(&img, w, h);
        dx[5 * w + 9] += 3.0; // an outlier: L1 and L2 disagree
        let c = Channel { width: w, height: h, primal: &img, dx: &dx, dy: &dy };
        let chans = [c.clone(), c.clone(), c.clone()];
        let params = IrlsParams::default();
        let l2 = solve_l2_dct(&c, 0.2);
        let full = solve_l1(&chans, 0.2, &params, &|| false);
        assert_eq!(solve_l1(&chans, 0.2, &params, &|| true)[0], l2);
        let asked = AtomicUsize::new(0);
        let one = solve_l1(&chans, 0.2, &params, &|| asked.fetch_add(1, Ordering::Relaxed) >= 4);
        let dist = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>();
        assert!(dist(&one[0], &l2) > 0.0 && dist(&one[0], &full[0]) < dist(&l2, &full[0]));
        let counted = AtomicUsize::new(0);
        solve_l1(&chans, 0.2, &params, &|| counted.fetch_add(1, Ordering::Relaxed) == usize::MAX);
        // once per outer iteration, and once per CG iteration (the channels are solved together)
        let per_outer = 1 + params.cg_iterations;
        let n = counted.load(Ordering::Relaxed);
        assert!(n > params.outer_iterations && n <= params.outer_iterations * per_outer, "{n}");
    }

    #[test]
    fn large_alpha_returns_the_primal() {
        let (w, h) = (16, 9);
        let img = test_image(w, h);
        let zero = vec![0.0; w * h];
        let c = Channel { width: w, height: h, primal: &img, dx: &zero, dy: &zero };
        let out = solve_l2_dct(&c, 1e4);
        for i in 0..w * h {
            assert!((out[i] - img[i]).abs() < 1e-6);
        }
    }

    #[test]
    fn one_outlier_gradient_rings_under_l2_not_under_l1() {
        let (w, h) = (32, 32);
        let img = vec![1.0; w * h];
        let (mut dx, dy) = gradients(&img, w, h);
        dx[16 * w + 16] = 50.0; // one wildly wrong gradient
        let c = Channel { width: w, height: h, primal: &img, dx: &dx, dy: &dy };
        let a = 0.2;
        let l2 = solve_l2_dct(&c, a);
        let chans = [c.clone(), c.clone(), c];
        let plain = IrlsParams { low_frequency_radius: 0, ..Default::default() };
        let l1 = solve_l1(&chans, a, &plain, &|| false);
        let err = |v: &[f64]| v.iter().map(|x| (x - 1.0).abs()).fold(0.0, f64::max);
        let spread = |v: &[f64]| v.iter().filter(|x| (**x - 1.0).abs() > 0.05).count();
        assert!(err(&l2) > 1.0 && spread(&l2) > 20, "L2 should smear the outlier: {} {}", err(&l2), spread(&l2));
        assert!(spread(&l1[0]) <= 2, "L1 should confine it: {} pixels off", spread(&l1[0]));
        // with the L2 solution's low frequencies (the default) only their smooth residue of
        // the dipole comes back: no ringing spike
        let kept = solve_l1(&chans, a, &IrlsParams::default(), &|| false);
        assert!(err(&kept[0]) < 0.1 * err(&l2), "{} vs L2 {}", err(&kept[0]), err(&l2));
    }
}
