//! Screened Poisson reconstruction of an image from a noisy primal I^g and its noisy
//! finite-difference gradients (docs/algorithm.md §5):
//!
//!   minimize  α²‖I − I^g‖² + ‖D_x I − I^dx‖² + ‖D_y I − I^dy‖²      (per channel)
//!
//! with forward differences and a free (Neumann) boundary: (D_x I)_i = I_{i+1} − I_i for
//! x < W−1, else 0. L2 is solved exactly by the DCT (Bhat et al. 2008); L1 by iteratively
//! reweighted least squares over conjugate gradients. Everything is f32 and row-planar
//! (`RowPlanar`), the integrators' own accumulation layout, so a render's buffers become the
//! problem without a copy (memory per pixel: docs/limits.md).

mod alpha;
mod cg;
mod dct;
mod irls;

pub use alpha::{chosen_alpha, HalfDifference, ALPHA_RANGE, FALLBACK_ALPHA};
pub use cg::{Problem, RowPlanar, Weights};
pub use dct::solve_l2;
pub use irls::{add_box_blur, solve_l1, IrlsParams};

use crate::film::Image;

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

impl Problem {
    /// The problem of a render's normalised primal and gradients (row-planar, f32).
    pub fn new(alpha: f64, primal: RowPlanar, dx: RowPlanar, dy: RowPlanar) -> Problem {
        Problem { alpha: alpha as f32, primal, dx, dy }
    }

    /// Its minimiser under `norm` (L1: by IRLS with `irls`'s schedule); an L1 solve returns
    /// early with its current iterate once `stop()` is true.
    pub fn reconstruct(&self, norm: Norm, irls: &IrlsParams, stop: &(dyn Fn() -> bool + Sync)) -> RowPlanar {
        match norm {
            Norm::L2 => solve_l2(self),
            Norm::L1 => solve_l1(self, irls, stop),
        }
    }
}

/// The gradient-domain image: the reconstruction plus the very-direct light (`direct`,
/// interleaved RGB), clipped at 0 (the screened Poisson solve is unconstrained and rings
/// slightly negative in the dark).
pub fn gradient_domain_image(
    p: &Problem,
    direct: &[f32],
    norm: Norm,
    irls: &IrlsParams,
    stop: &(dyn Fn() -> bool + Sync),
) -> Image {
    let data = p.reconstruct(norm, irls, stop).to_interleaved(Some(direct), 0.0);
    Image { width: p.width(), height: p.height(), channels: 3, data }
}

/// The layers of a gradient-domain render, made from its problem and very-direct image
/// (both consumed, so that no image is held twice): Combined (the gradient-domain image),
/// GD Primal (primal + very direct), GD Gradient X and Y, Very Direct.
pub fn gradient_domain_layers(
    p: Problem,
    direct: Vec<f32>,
    norm: Norm,
    irls: &IrlsParams,
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<(String, Image)> {
    let (w, h) = (p.width(), p.height());
    let img = |data: Vec<f32>| Image { width: w, height: h, channels: 3, data };
    let combined = img(p.reconstruct(norm, irls, stop).to_interleaved(Some(&direct), 0.0));
    let Problem { primal, dx, dy, .. } = p;
    let primal = img(primal.to_interleaved(Some(&direct), f32::NEG_INFINITY));
    let dx = img(dx.to_interleaved(None, f32::NEG_INFINITY));
    let dy = img(dy.to_interleaved(None, f32::NEG_INFINITY));
    vec![
        ("Combined".into(), combined),
        ("GD Primal".into(), primal),
        ("GD Gradient X".into(), dx),
        ("GD Gradient Y".into(), dy),
        ("Very Direct".into(), img(direct)),
    ]
}

/// Reconstructs an RGB image from interleaved primal, dx, dy (W·H·3 each; a non-finite value
/// counts as 0); returns it interleaved.
#[allow(clippy::too_many_arguments)]
pub fn reconstruct_rgb(
    w: usize,
    h: usize,
    primal: &[f32],
    dx: &[f32],
    dy: &[f32],
    alpha: f64,
    norm: Norm,
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<f32> {
    let planar = |v: &[f32]| RowPlanar::from_interleaved(v, w, h, 1.0);
    let p = Problem::new(alpha, planar(primal), planar(dx), planar(dy));
    p.reconstruct(norm, &IrlsParams::default(), stop).to_interleaved(None, f32::NEG_INFINITY)
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

    /// The problem whose three channels are the same grey (primal, dx, dy) planes.
    fn grey(w: usize, h: usize, alpha: f64, primal: &[f64], dx: &[f64], dy: &[f64]) -> Problem {
        let rp = |v: &[f64]| RowPlanar::from_planes([v, v, v], w, h);
        Problem::new(alpha, rp(primal), rp(dx), rp(dy))
    }

    fn max_diff(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

    #[test]
    fn exact_gradients_reconstruct_the_image() {
        let (w, h) = (23, 17);
        let img = test_image(w, h);
        let (dx, dy) = gradients(&img, w, h);
        // Exact primal and gradients: the image itself is the minimiser for any α.
        let p = grey(w, h, 0.2, &img, &dx, &dy);
        let l2 = solve_l2(&p);
        let l1 = solve_l1(&p, &IrlsParams::default(), &|| false);
        for c in 0..3 {
            assert!(max_diff(&l2.plane(c), &img) < 1e-5, "dct {}", max_diff(&l2.plane(c), &img));
            assert!(max_diff(&l1.plane(c), &img) < 1e-5, "l1 {}", max_diff(&l1.plane(c), &img));
        }
        // A noisy primal with exact gradients: as α → 0 only the primal's mean survives.
        let mut s = IndependentSampler::new(1, 1);
        let noisy: Vec<f64> = img.iter().map(|v| v + (s.next_1d() as f64 - 0.5)).collect();
        let shift = img.iter().zip(&noisy).map(|(a, b)| a - b).sum::<f64>() / (w * h) as f64;
        let shifted: Vec<f64> = img.iter().map(|v| v - shift).collect();
        let a = 1e-2;
        let l2 = solve_l2(&grey(w, h, a, &noisy, &dx, &dy)).plane(0);
        // deviation ≤ α²·|noise|/λ_min ≈ 1e-4·0.5/0.0187 ≈ 3e-3
        assert!(max_diff(&l2, &shifted) < 3e-3, "dct {}", max_diff(&l2, &shifted));
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
        let chans: Vec<[Vec<f64>; 3]> = (0..3).map(|_| [noisy(&img), noisy(&dx), noisy(&dy)]).collect();
        let planes = |k: usize| RowPlanar::from_planes([&chans[0][k], &chans[1][k], &chans[2][k]], w, h);
        let p = Problem::new(0.2, planes(0), planes(1), planes(2));
        let solve = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            let mut x = RowPlanar::zeros(w, h);
            pool.install(|| p.solve(&Weights::ones(w, h), &mut x, 400, 1e-7, &|| false));
            x
        };
        let (one, two) = (solve(1), solve(2));
        assert_eq!(one, two);
        let exact = solve_l2(&p);
        for c in 0..3 {
            assert!(max_diff(&one.plane(c), &exact.plane(c)) < 1e-4, "{}", max_diff(&one.plane(c), &exact.plane(c)));
        }
    }

    /// The f32 DCT solve is the minimiser: A·x = b holds to f32 precision (the CG's operator
    /// applied to it), on an image of unequal sides and three different channels.
    #[test]
    fn dct_solution_satisfies_the_normal_equations() {
        let (w, h) = (31, 20);
        let mut s = IndependentSampler::new(9, 3);
        let mut rnd = || -> Vec<f64> { (0..w * h).map(|_| s.next_1d() as f64 * 2.0 - 1.0).collect() };
        let ch: Vec<[Vec<f64>; 3]> = (0..3).map(|_| [rnd(), rnd(), rnd()]).collect();
        let planes = |k: usize| RowPlanar::from_planes([&ch[0][k], &ch[1][k], &ch[2][k]], w, h);
        let p = Problem::new(0.3, planes(0), planes(1), planes(2));
        let x = solve_l2(&p);
        let (ax, b) = p.operator_and_rhs(&Weights::ones(w, h), &x);
        let scale = b.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let err = ax.data.iter().zip(&b.data).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(err < 2e-5 * scale, "‖Ax − b‖∞ = {err} (‖b‖∞ = {scale})");
    }

    /// IRLS's fused reweighting and set-up pass gives the weights 1/(‖e‖_RGB + reg) of
    /// their definition (`irls_weights`, written from the residual rows) bit for bit, and the
    /// residual r = b − A·x of the normal equations under them; across bands, the last one a
    /// single row.
    #[test]
    fn the_fused_reweighting_is_the_weights_and_residual_of_their_definitions() {
        let (w, h) = (19, 2 * cg::BAND + 1);
        let mut s = IndependentSampler::new(11, 4);
        let mut rnd = || -> Vec<f64> { (0..w * h).map(|_| s.next_1d() as f64 * 2.0 - 1.0).collect() };
        let ch: Vec<[Vec<f64>; 4]> = (0..3).map(|_| [rnd(), rnd(), rnd(), rnd()]).collect();
        let planes = |k: usize| RowPlanar::from_planes([&ch[0][k], &ch[1][k], &ch[2][k]], w, h);
        let p = Problem::new(0.3, planes(0), planes(1), planes(2));
        let mut x = planes(3);
        let reg = 0.05f32;
        let mut want = Weights::ones(w, h);
        irls::irls_weights(&p, &x, reg, &mut want);
        let (mut got, mut ws) = (Weights::ones(w, h), cg::Workspace::new(w, h));
        let x0 = x.clone();
        p.solve_reweighted_in(&mut ws, &mut got, &mut x, |n| 1.0 / (n + reg), 0, 1e-10, &|| false);
        assert_eq!(x, x0, "no CG step was asked for");
        assert_eq!((&got.g, &got.x, &got.y), (&want.g, &want.x, &want.y));
        let (ax, b) = p.operator_and_rhs(&want, &x);
        let scale = b.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        for (i, ((r, a), b)) in ws.residual().data.iter().zip(&ax.data).zip(&b.data).enumerate() {
            assert!((r - (b - a)).abs() < 1e-5 * scale, "entry {i}: r {r} vs b − Ax {}", b - a);
        }
    }

    /// An L1 solve returns the same image bit for bit on one thread and on two (the bands'
    /// dot products are summed in band order; each band recomputes its neighbours' rows).
    #[test]
    fn l1_ignores_the_thread_count() {
        let (w, h) = (23, 3 * cg::BAND + 2);
        let img = test_image(w, h);
        let (mut dx, dy) = gradients(&img, w, h);
        dx[7 * w + 5] += 2.0;
        let p = grey(w, h, 0.2, &img, &dx, &dy);
        let solve = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| solve_l1(&p, &IrlsParams::default(), &|| false))
        };
        assert_eq!(solve(1), solve(2));
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
        let p = grey(w, h, 0.2, &img, &dx, &dy);
        let params = IrlsParams::default();
        let l2 = solve_l2(&p).plane(0);
        let full = solve_l1(&p, &params, &|| false).plane(0);
        assert_eq!(solve_l1(&p, &params, &|| true).plane(0), l2);
        let asked = AtomicUsize::new(0);
        let one = solve_l1(&p, &params, &|| asked.fetch_add(1, Ordering::Relaxed) >= 4).plane(0);
        let dist = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>();
        assert!(dist(&one, &l2) > 0.0 && dist(&one, &full) < dist(&l2, &full));
        let counted = AtomicUsize::new(0);
        solve_l1(&p, &params, &|| counted.fetch_add(1, Ordering::Relaxed) == usize::MAX);
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
        let out = solve_l2(&grey(w, h, 1e4, &img, &zero, &zero)).plane(1);
        assert!(max_diff(&out, &img) < 1e-5, "{}", max_diff(&out, &img));
    }

    #[test]
    fn one_outlier_gradient_rings_under_l2_not_under_l1() {
        let (w, h) = (32, 32);
        let img = vec![1.0; w * h];
        let (mut dx, dy) = gradients(&img, w, h);
        dx[16 * w + 16] = 50.0; // one wildly wrong gradient
        let p = grey(w, h, 0.2, &img, &dx, &dy);
        let l2 = solve_l2(&p).plane(0);
        let plain = IrlsParams { low_frequency_radius: 0, ..Default::default() };
        let l1 = solve_l1(&p, &plain, &|| false).plane(0);
        let err = |v: &[f64]| v.iter().map(|x| (x - 1.0).abs()).fold(0.0, f64::max);
        let spread = |v: &[f64]| v.iter().filter(|x| (**x - 1.0).abs() > 0.05).count();
        assert!(err(&l2) > 1.0 && spread(&l2) > 20, "L2 should smear the outlier: {} {}", err(&l2), spread(&l2));
        assert!(spread(&l1) <= 2, "L1 should confine it: {} pixels off", spread(&l1));
        // with the L2 solution's low frequencies (the default) only their smooth residue of
        // the dipole comes back: no ringing spike
        let kept = solve_l1(&p, &IrlsParams::default(), &|| false).plane(0);
        assert!(err(&kept) < 0.1 * err(&l2), "{} vs L2 {}", err(&kept), err(&l2));
    }

    /// The layers of a gradient-domain render: Combined is the reconstruction plus the very
    /// direct light clipped at 0, GD Primal the primal plus it, the gradients as given; an
    /// interleaved ↔ row-planar round trip is exact.
    #[test]
    fn gradient_domain_layers_are_their_definitions() {
        let (w, h) = (9, 6);
        let mut s = IndependentSampler::new(5, 5);
        let mut rnd = || -> Vec<f32> { (0..3 * w * h).map(|_| s.next_1d() * 2.0 - 0.5).collect() };
        let (primal, dx, dy, direct) = (rnd(), rnd(), rnd(), rnd());
        let rp = |v: &[f32]| RowPlanar::from_interleaved(v, w, h, 1.0);
        assert_eq!(rp(&primal).to_interleaved(None, f32::NEG_INFINITY), primal);
        let p = Problem::new(0.2, rp(&primal), rp(&dx), rp(&dy));
        let recon = solve_l2(&p).to_interleaved(None, f32::NEG_INFINITY);
        let layers = gradient_domain_layers(p, direct.clone(), Norm::L2, &IrlsParams::default(), &|| false);
        let names: Vec<&str> = layers.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["Combined", "GD Primal", "GD Gradient X", "GD Gradient Y", "Very Direct"]);
        for i in 0..3 * w * h {
            assert_eq!(layers[0].1.data[i], (recon[i] + direct[i]).max(0.0));
            assert_eq!(layers[1].1.data[i], primal[i] + direct[i]);
        }
        assert_eq!((&layers[2].1.data, &layers[3].1.data, &layers[4].1.data), (&dx, &dy, &direct));
        assert!(recon.iter().zip(&direct).any(|(r, d)| r + d < 0.0)); // the clip was exercised
    }
}
