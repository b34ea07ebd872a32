//! L1 reconstruction by iteratively reweighted least squares: start from the exact L2
//! solution, then weight each residual row by 1/(‖e‖_RGB + reg_k) (reg_k = reg₀·decay^(k−1))
//! and re-solve by warm-started CG. RGB channels share
//! their weights, so an outlier in one channel is treated as an outlier in all.
//!
//! The L1 minimiser is a robust estimator: it discards the energy of rare bright samples
//! (a caustic through glass, a light seen through a gap), so at low sample counts its image
//! is darker than the truth (measured: gdpt on the bulb scene −20% at 32 spp, the Cornell box
//! without NEE −10%), converging only as the noise vanishes. Its low frequencies are
//! therefore replaced by the unbiased L2 solution's: result = L1 + B(L2) − B(L1), with B a
//! box filter of radius `low_frequency_radius` (reflected at the border, so it keeps the
//! image sum: the result has exactly the L2 image's mean). Measured at 64², 4 seeds: bias
//! within ±2% where it was −10% to −20%, relMSE equal or lower for gdpt, up to 1.2× for
//! gdpssmlt.

#[cfg(test)]
use super::cg::BAND;
use super::cg::{Problem, RowPlanar, Weights, Workspace};
use super::dct::solve_l2;
use rayon::prelude::*;

#[derive(Clone, Debug)]
pub struct IrlsParams {
    pub outer_iterations: usize,
    pub cg_iterations: usize,
    pub reg0: f64,
    pub decay: f64,
    /// Radius (pixels) of the box filter whose band comes from the L2 solution; 0 = plain L1.
    pub low_frequency_radius: usize,
}

impl Default for IrlsParams {
    /// The schedule for gdpssmlt. The public GDPT code uses 20 × 50. Measured on GDPT and
    /// GDPSSMLT renders of the Cornell box (96², 16 and 64 per pixel, relMSE against PT at
    /// 4096 spp, 2026-11-25): 10 × 10 warm-started iterations land within ±1% of 20 × 50 at
    /// 1/7 of the time; 5 × 20 is up to 13% worse, plain L2 up to 60% worse. On gdpssmlt
    /// renders (192² Cornell box and gap, 8 and 32 mutations per pixel, 3 seeds, 2026-12-02)
    /// fewer reweightings lose: 4 × 10 is 5–15% worse than 10 × 10, 20 × 50 2–3% better.
    /// Fewer CG steps per reweighting lose less (same renders, 8 bounces, relMSE ÷ 10 × 10's,
    /// fifth session): 10 × 6 1.02, 10 × 5 1.03, 13 × 4 1.03, 8 × 8 1.02, 6 × 10 1.03, 20 × 2 1.13;
    /// 10 × 6 took 0.96–1.18 s at 1920×1080 where 10 × 10 took 1.45–1.6 s (2 cores), so it is
    /// the default: at 1080p the half second it saves buys more samples than the 2% it costs
    /// within a render of up to about 20 s.
    fn default() -> Self {
        IrlsParams { outer_iterations: 10, cg_iterations: 6, reg0: 0.05, decay: 0.5, low_frequency_radius: 8 }
    }
}

impl IrlsParams {
    /// The schedule for gdpt: 4 reweightings of 10 CG steps, the regulariser falling 6× each
    /// time (to about where 10 halvings take it). On gdpt renders (192² Cornell box and gap,
    /// 8 and 32 spp, 3 seeds, relMSE against pt at 4096 spp, 2026-12-02) it is within 0.5% of
    /// 10 × 10 on the box and 7–16% better on the gap — gdpt's independent samples gain
    /// nothing from a closer approach to the L1 minimiser, which suppresses true detail with
    /// the outliers — at 40% of the time (0.75–0.85 s instead of 1.75–1.9 s at 1920×1080 on
    /// 2 cores).
    pub fn short() -> Self {
        IrlsParams { outer_iterations: 4, cg_iterations: 10, decay: 0.16, ..Default::default() }
    }
}

/// The IRLS weight of a residual row, from its RGB norm: 1/(‖e‖_RGB + reg). Not normalised:
/// a common factor of all row weights leaves the weighted minimiser unchanged (the reference
/// implementation's normalisation to mean 1 was a pass over the image for nothing).
#[inline]
fn irls_weight(norm: f32, reg: f32) -> f32 {
    1.0 / (norm + reg)
}

/// The IRLS weights of the residual rows at `sol`, written out on their own (the last
/// column's x rows and the last row's y rows do not exist: 0). The solve computes them inside
/// its set-up pass (`Problem::solve_reweighted_in`); this is its reference in the tests.
#[cfg(test)]
pub(super) fn irls_weights(p: &Problem, sol: &RowPlanar, reg: f32, wts: &mut Weights) {
    let (w, h) = (p.width(), p.height());
    let Weights { g, x: wx, y: wy } = wts;
    g.par_chunks_mut(BAND * w).zip(wx.par_chunks_mut(BAND * w).zip(wy.par_chunks_mut(BAND * w))).enumerate().for_each(
        |(b, (gb, (xb, yb)))| {
            let (mut eg, mut ex, mut ey) = (vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]);
            for (k, ((gr, xr), yr)) in
                gb.chunks_exact_mut(w).zip(xb.chunks_exact_mut(w)).zip(yb.chunks_exact_mut(w)).enumerate()
            {
                let y = b * BAND + k;
                eg.fill(0.0);
                ex.fill(0.0);
                ey.fill(0.0);
                for c in 0..3 {
                    let (s, pr, gx, gy) = (sol.row(y, c), p.primal.row(y, c), p.dx.row(y, c), p.dy.row(y, c));
                    for ((e, &si), &pi) in eg.iter_mut().zip(s).zip(pr) {
                        *e += (p.alpha * (si - pi)).powi(2);
                    }
                    for ((e, &gi), (&si, &sn)) in ex.iter_mut().zip(gx).zip(s.iter().zip(&s[1..])) {
                        *e += (sn - si - gi).powi(2);
                    }
                    if y + 1 < h {
                        for ((e, &gi), (&si, &sn)) in ey.iter_mut().zip(gy).zip(s.iter().zip(sol.row(y + 1, c))) {
                            *e += (sn - si - gi).powi(2);
                        }
                    }
                }
                for (o, e) in gr.iter_mut().zip(&eg) {
                    *o = irls_weight(e.sqrt(), reg);
                }
                for (o, e) in xr[..w - 1].iter_mut().zip(&ex) {
                    *o = irls_weight(e.sqrt(), reg);
                }
                if y + 1 < h {
                    for (o, e) in yr.iter_mut().zip(&ey) {
                        *o = irls_weight(e.sqrt(), reg);
                    }
                }
            }
        },
    );
}

/// `stop` is asked between outer iterations and inside every CG iteration: when it turns true
/// (Esc), the current iterate — the L2 solution refined so far — is returned.
pub fn solve_l1(p: &Problem, params: &IrlsParams, stop: &(dyn Fn() -> bool + Sync)) -> RowPlanar {
    let (w, h) = (p.width(), p.height());
    let mut sol = solve_l2(p);
    if params.outer_iterations == 0 || stop() {
        return sol; // stopped before the first reweighting: the exact L2 solution
    }
    // the L2 solution, for its low frequencies: result = L1 + B(L2) − B(L1) = L1 + B(L2 − L1)
    // (B is linear), one blur at the end
    let r = params.low_frequency_radius;
    let l2 = (r > 0).then(|| sol.clone());
    let mut reg = params.reg0;
    // allocated once: fresh pages every reweighting cost as much as a CG step
    let mut wts = Weights::zeros(w, h); // every entry is written by the first reweighting
    let mut ws = Workspace::new(w, h);
    for k in 0..params.outer_iterations {
        if k > 0 && stop() {
            break;
        }
        let regf = reg as f32;
        // tolerance 0: a few CG steps never reach a relative residual of any use as a stop,
        // and without one the set-up need not sum ‖b‖² (measured 2.5 ms of its 21 at 1080p)
        p.solve_reweighted_in(&mut ws, &mut wts, &mut sol, |n| irls_weight(n, regf), params.cg_iterations, 0.0, stop);
        reg *= params.decay;
    }
    drop((wts, ws));
    if let Some(mut diff) = l2 {
        diff.data.par_iter_mut().zip(&sol.data).for_each(|(d, &l1)| *d -= l1);
        add_box_blur(&mut diff, r, &mut sol);
    }
    sol
}

/// Index of k ∈ [−n, 2n) in a line of n samples reflected at both ends (half-sample
/// symmetric, as the DCT's boundary), for any k (period 2n).
#[inline]
fn reflect(k: isize, n: usize) -> usize {
    let m = k.rem_euclid(2 * n as isize) as usize;
    if m < n {
        m
    } else {
        2 * n - 1 - m
    }
}

/// dst += B(src) for the three channels of row-planar images, B the box filter of radius r
/// with each channel reflected at its border (half-sample symmetric, as the DCT's boundary):
/// a symmetric, doubly stochastic operator, so it keeps the image sum. Separable, by running
/// sums in f64: O(W·H) whatever r, three passes over the image in all; `src` is left blurred
/// along its rows.
pub fn add_box_blur(src: &mut RowPlanar, r: usize, dst: &mut RowPlanar) {
    let (w, h) = (src.width, src.height);
    let norm = 1.0 / (2 * r + 1) as f64;
    let ri = r as isize;
    // rows: every channel's row on its own, in place from a copy
    src.data.par_chunks_mut(w).for_each_init(
        || vec![0.0f32; w],
        |copy, row| {
            copy.copy_from_slice(row);
            let mut acc: f64 = (-ri..=ri).map(|k| copy[reflect(k, w)] as f64).sum();
            for (x, o) in row.iter_mut().enumerate() {
                *o = (acc * norm) as f32;
                let xi = x as isize;
                acc += copy[reflect(xi + ri + 1, w)] as f64 - copy[reflect(xi - ri, w)] as f64;
            }
        },
    );
    // columns, added to dst: bands of rows in parallel, each sliding a row (three channels)
    // of running sums down its band
    const ROWS: usize = 64;
    let row3 = 3 * w;
    let rows: &RowPlanar = src;
    dst.data.par_chunks_mut(ROWS * row3).enumerate().for_each(|(b, band)| {
        let row = |y: isize| &rows.data[reflect(y, h) * row3..(reflect(y, h) + 1) * row3];
        let y0 = (b * ROWS) as isize;
        let mut acc = vec![0.0f64; row3];
        for k in -ri..=ri {
            for (a, &v) in acc.iter_mut().zip(row(y0 + k)) {
                *a += v as f64;
            }
        }
        for (k, out) in band.chunks_exact_mut(row3).enumerate() {
            for (o, &a) in out.iter_mut().zip(&acc) {
                *o += (a * norm) as f32;
            }
            let y = y0 + k as isize;
            for ((a, &p), &m) in acc.iter_mut().zip(row(y + ri + 1)).zip(row(y - ri)) {
                *a += p as f64 - m as f64;
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut s = IndependentSampler::new(seed, 0);
        (0..n).map(|_| s.next_1d()).collect()
    }

    /// One plane through `add_box_blur` (in channel 1, the others zero; dst zero).
    fn box_blur(v: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
        let mut src = RowPlanar::zeros(w, h);
        src.set_channel(1, v);
        let mut dst = RowPlanar::zeros(w, h);
        add_box_blur(&mut src, r, &mut dst);
        assert!(dst.channel(0).iter().chain(&dst.channel(2)).all(|&a| a == 0.0), "channels stay apart");
        dst.channel(1)
    }

    /// The reflected box filter keeps the image sum, is symmetric (⟨Bx, y⟩ = ⟨x, By⟩),
    /// leaves a constant image alone and is the identity at radius 0 — also when the radius
    /// exceeds the image, and across the parallel bands of rows (h > 64).
    #[test]
    fn box_blur_is_symmetric_and_keeps_the_sum() {
        for (w, h, r) in [(13, 7, 2), (16, 16, 8), (5, 3, 9), (1, 4, 1), (7, 150, 3)] {
            let (x, y) = (noise(w * h, 1), noise(w * h, 2));
            let (bx, by) = (box_blur(&x, w, h, r), box_blur(&y, w, h, r));
            let sum = |v: &[f32]| v.iter().map(|&a| a as f64).sum::<f64>();
            assert!(
                (sum(&bx) - sum(&x)).abs() < 1e-6 * (w * h) as f64,
                "{w}×{h} r={r}: sum {} vs {}",
                sum(&bx),
                sum(&x)
            );
            let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(p, q)| (p * q) as f64).sum::<f64>();
            assert!((dot(&bx, &y) - dot(&x, &by)).abs() < 1e-6 * (w * h) as f64);
            assert!(box_blur(&vec![0.7; w * h], w, h, r).iter().all(|v| (v - 0.7).abs() < 1e-6));
            assert_eq!(box_blur(&x, w, h, 0), x);
        }
    }

    /// Against the definition, each channel its own: dst gains the mean of the (2r+1)²
    /// reflected neighbours — across the parallel bands of rows (h > 64), with a radius beyond
    /// the image, and on images one pixel wide.
    #[test]
    fn planar_blur_adds_the_mean_of_the_reflected_neighbours() {
        for (w, h, r) in [(13, 150, 3), (5, 3, 9), (1, 70, 2), (40, 20, 8)] {
            let planes: Vec<Vec<f64>> =
                (0..3).map(|c| noise(w * h, 10 + c as u64).iter().map(|&v| v as f64).collect()).collect();
            let mut src = RowPlanar::from_planes([&planes[0], &planes[1], &planes[2]], w, h);
            let base = RowPlanar::from_planes([&planes[2], &planes[0], &planes[1]], w, h);
            let mut dst = base.clone();
            add_box_blur(&mut src, r, &mut dst);
            let ri = r as isize;
            for (c, plane) in planes.iter().enumerate() {
                let (b, got) = (base.channel(c), dst.channel(c));
                for (py, px) in (0..h).flat_map(|y| (0..w).map(move |x| (y, x))) {
                    let mut s = 0.0f64;
                    for dy in -ri..=ri {
                        for dx in -ri..=ri {
                            s += plane[reflect(py as isize + dy, h) * w + reflect(px as isize + dx, w)];
                        }
                    }
                    let want = b[py * w + px] as f64 + s / ((2 * r + 1) * (2 * r + 1)) as f64;
                    let i = py * w + px;
                    assert!(
                        (got[i] as f64 - want).abs() < 1e-5,
                        "{w}×{h} r={r} channel {c} ({px}, {py}): {} vs {want}",
                        got[i]
                    );
                }
            }
        }
    }

    /// Noisy primal and gradients with rare bright outliers (as a caustic gives): plain L1
    /// loses their energy (its image mean is below the L2 one, which is unbiased); with the
    /// L2 solution's low frequencies the mean is the L2 mean, and the result is still closer
    /// to the truth than the L2 solution at the outliers' pixels.
    #[test]
    fn l1_keeps_the_unbiased_low_frequencies() {
        let (w, h) = (32, 24);
        let truth: Vec<f64> = (0..w * h).map(|i| 1.0 + 0.5 * ((i % w) as f64 * 0.2).sin()).collect();
        let (tdx, tdy) = super::super::gradients(&truth, w, h);
        let mut s = IndependentSampler::new(3, 3);
        // an estimator with mean = truth: most samples a bit low, a few 8× high
        let mut spike = |v: f64| if s.next_1d() < 0.05 { v * 8.0 } else { v * (1.0 - 0.05 * 7.0) / 0.95 };
        let primal: Vec<f64> = truth.iter().map(|&v| spike(v)).collect();
        let dx: Vec<f64> = tdx.iter().map(|&v| v + 0.02 * (spike(1.0) - 1.0)).collect();
        let dy: Vec<f64> = tdy.iter().map(|&v| v + 0.02 * (spike(1.0) - 1.0)).collect();
        let rp = |v: &[f64]| RowPlanar::from_planes([v, v, v], w, h);
        let p = Problem { alpha: 0.2, primal: rp(&primal), dx: rp(&dx), dy: rp(&dy) };
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let l2 = solve_l2(&p).plane(0);
        let plain = solve_l1(&p, &IrlsParams { low_frequency_radius: 0, ..Default::default() }, &|| false).plane(0);
        let kept = solve_l1(&p, &IrlsParams::default(), &|| false).plane(0);
        assert!(mean(&plain) < mean(&l2) - 0.02, "plain L1 {} vs L2 {}", mean(&plain), mean(&l2));
        assert!((mean(&kept) - mean(&l2)).abs() < 1e-5, "{} vs {}", mean(&kept), mean(&l2));
        let err = |v: &[f64]| v.iter().zip(&truth).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        assert!(err(&kept) < err(&l2), "L1 with L2 lows {} vs L2 {}", err(&kept), err(&l2));
    }
}
