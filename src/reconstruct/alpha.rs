//! The screened-Poisson weight α chosen from the render's own noise (docs/algorithm.md §5,
//! "choosing α").
//!
//! α weighs the primal against the gradients, α²‖I − I^g‖² + ‖D I − I^d‖². A small α lets
//! the gradients carry the image: right where they are much cleaner than the primal (hard
//! shadows, glossy highlights: a one-pixel shift changes little), wrong where they are about
//! as noisy (light from the whole sky: a one-pixel shift changes what the sky sample sees
//! about as often as the primal's own samples differ). No constant fits both; the measure is
//! in the render itself.
//!
//! The integrator splits its samples into two halves by sample index (even, odd) and keeps,
//! per pixel, only the channel mean of A − B for the primal and both gradients (12 bytes per
//! pixel, [`HalfDifference`]). The image cancels in A − B; what is left is each buffer's
//! noise. Then
//!
//!   α = mean |Δ I^dx, Δ I^dy| / mean |Δ I^g|
//!
//! the gradients' noise over the primal's, on the L1 scale (mean absolute values, not mean
//! squares: gradient noise is heavy-tailed, a few failed or occluded shifts, which the L1
//! reconstruction discounts anyway; differences beyond [`OUTLIER_CAP`] times the primal's
//! mean count as that). Measured on seven scenes at 32 and 96 spp against 14 fixed values
//! (docs/algorithm.md §5): 2% above the best on average, 9% at most; the old fixed 0.2 was
//! up to 31% worse (under a sky).

use super::RowPlanar;

/// α where the render cannot measure it (a single sample, a black image).
pub const FALLBACK_ALPHA: f64 = 0.2;
/// The measured α is kept within these bounds (the measures seen on real scenes: 0.25–0.9).
pub const ALPHA_RANGE: (f64, f64) = (0.02, 5.0);
/// Differences above this many times the primal's mean |Δ| count as this much: the L1
/// reconstruction drops such outliers (rare shifts that carry a whole path's light), so
/// they must not make the gradients look noisier than the reconstruction finds them.
/// Measured (`gdpt`, 32 and 96 spp, seven scenes, error ÷ the best fixed α): caps of 4, 8,
/// 16 all 1.02 on average; uncapped 1.035, 1.14 on the door ajar (1.03 with 8).
pub const OUTLIER_CAP: f64 = 8.0;

/// The α a reconstruction uses for the setting `setting`: the setting where it is > 0; where
/// it is 0 (automatic) the `measured` one, or [`FALLBACK_ALPHA`] where nothing was measured.
pub fn chosen_alpha(setting: f64, measured: impl FnOnce() -> Option<f64>) -> f64 {
    if setting > 0.0 {
        setting
    } else {
        measured().unwrap_or(FALLBACK_ALPHA)
    }
}

/// Per pixel, the channel mean of (sum of the even half's samples − sum of the odd half's),
/// for the primal and the two gradients, in the scale of the render's accumulators; and how
/// many samples (or chains) each half holds.
pub struct HalfDifference {
    pub width: usize,
    pub height: usize,
    pub primal: Vec<f32>,
    pub dx: Vec<f32>,
    pub dy: Vec<f32>,
    /// Samples in the even half and in the odd half.
    pub counts: [u64; 2],
}

impl HalfDifference {
    pub fn zeros(width: usize, height: usize) -> HalfDifference {
        let n = width * height;
        HalfDifference { width, height, primal: vec![0.0; n], dx: vec![0.0; n], dy: vec![0.0; n], counts: [0; 2] }
    }

    /// The sign a sample of index `s` is accumulated with.
    #[inline]
    pub fn sign(s: u64) -> f32 {
        if s.is_multiple_of(2) {
            1.0
        } else {
            -1.0
        }
    }

    /// Counts samples [from, to) into their halves.
    pub fn count(&mut self, from: u64, to: u64) {
        let even = to.div_ceil(2) - from.div_ceil(2);
        self.counts[0] += even;
        self.counts[1] += (to - from) - even;
    }

    /// α = mean |Δ gradient| / mean |Δ primal|, Δ the difference of the halves' means per
    /// pixel, each |Δ| capped at [`OUTLIER_CAP`] × the primal's mean |Δ|, over the gradients
    /// that exist (not past the last column or row), clamped to [`ALPHA_RANGE`]; None where
    /// it is not measured (a half empty, no noise at all).
    /// `sums`: the primal, dx and dy accumulators (both halves), row-planar, in the scale of
    /// the differences.
    pub fn alpha(&self, sums: [&RowPlanar; 3]) -> Option<f64> {
        let (w, h) = (self.width, self.height);
        let [na, nb] = self.counts.map(|n| n as f64);
        if !(na > 0.0 && nb > 0.0) {
            return None;
        }
        let mean_abs = |d: &[f32], sum: &RowPlanar, keep: &dyn Fn(usize, usize) -> bool, cap: f64| {
            let (mut total, mut n) = (0.0f64, 0usize);
            for y in 0..h {
                for x in 0..w {
                    if keep(x, y) {
                        let s = (0..3).map(|c| sum.data[(3 * y + c) * w + x] as f64).sum::<f64>() / 3.0;
                        let diff = d[y * w + x] as f64;
                        // A = (S + D)/2, B = (S − D)/2: the halves' means differ by
                        total += ((s + diff) / (2.0 * na) - (s - diff) / (2.0 * nb)).abs().min(cap);
                        n += 1;
                    }
                }
            }
            (n > 0).then(|| total / n as f64)
        };
        let [primal, dx, dy] = sums;
        let cap = OUTLIER_CAP * mean_abs(&self.primal, primal, &|_, _| true, f64::INFINITY)?;
        let p = mean_abs(&self.primal, primal, &|_, _| true, cap)?;
        let gx = mean_abs(&self.dx, dx, &|x, _| x + 1 < w, cap);
        let gy = mean_abs(&self.dy, dy, &|_, y| y + 1 < h, cap);
        let g = match (gx, gy) {
            (Some(a), Some(b)) => 0.5 * (a + b),
            (a, b) => a.or(b)?,
        };
        let alpha = g / p;
        (alpha.is_finite() && alpha > 0.0).then(|| alpha.clamp(ALPHA_RANGE.0, ALPHA_RANGE.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    /// Accumulates `n` samples of (image + σ_p·u, image/10 + σ_g·u, σ_g·u) per pixel, u
    /// uniform in [−1, 1): sums and half differences, as an integrator does.
    fn render(w: usize, h: usize, n: u64, sp: f32, sg: f32) -> (HalfDifference, [RowPlanar; 3]) {
        let mut d = HalfDifference::zeros(w, h);
        let mut sums = [0; 3].map(|_| RowPlanar::zeros(w, h));
        let mut rng = IndependentSampler::new(7, 0);
        for s in 0..n {
            let sign = HalfDifference::sign(s);
            for y in 0..h {
                for x in 0..w {
                    let image = ((x * 7 + y * 3) % 11) as f32 * 0.3;
                    let mut u = || 2.0 * rng.next_1d() - 1.0;
                    // the last column's dx and last row's dy do not exist: huge, to be ignored
                    let v = [
                        image + sp * u(),
                        if x + 1 < w { 0.1 * image + sg * u() } else { 1e6 },
                        if y + 1 < h { sg * u() } else { -1e6 },
                    ];
                    for (k, v) in v.into_iter().enumerate() {
                        let c = [v, 2.0 * v, 0.0]; // channel mean = v
                        for (ch, c) in c.into_iter().enumerate() {
                            sums[k].data[(3 * y + ch) * w + x] += c;
                        }
                        let half = match k {
                            0 => &mut d.primal,
                            1 => &mut d.dx,
                            _ => &mut d.dy,
                        };
                        half[y * w + x] += sign * v;
                    }
                }
            }
            d.count(s, s + 1);
        }
        (d, sums)
    }

    /// Noise of known scale gives α ≈ σ_g / σ_p (the mean absolute difference of two means of
    /// uniform noise is the same multiple of σ for both), whatever the image, for an odd
    /// sample count too (the halves' means are compared, not their sums).
    #[test]
    fn alpha_is_the_ratio_of_the_noise_scales() {
        for (n, sp, sg) in [(16, 0.1f32, 0.03f32), (15, 0.02, 0.05), (9, 1.0, 0.4)] {
            let (d, sums) = render(64, 48, n, sp, sg);
            let a = d.alpha([&sums[0], &sums[1], &sums[2]]).unwrap();
            assert!((a / (sg / sp) as f64 - 1.0).abs() < 0.04, "n {n} σp {sp} σg {sg}: α = {a}");
        }
    }

    /// Rare huge gradient differences (a shift carrying a whole path's light) are capped: a
    /// thousandth of the gradients at 10⁴ × σ_g moves α by a few percent, not 10×.
    #[test]
    fn rare_gradient_outliers_are_capped() {
        let (mut d, sums) = render(64, 48, 16, 0.1, 0.03);
        let base = d.alpha([&sums[0], &sums[1], &sums[2]]).unwrap();
        for i in (0..d.dx.len()).step_by(1000) {
            d.dx[i] += 300.0;
        }
        let a = d.alpha([&sums[0], &sums[1], &sums[2]]).unwrap();
        assert!(a > base && a < 1.1 * base, "α {base} → {a}");
    }

    /// Counting in passes of any size splits the samples as their indices do.
    #[test]
    fn passes_count_their_samples_into_the_halves() {
        let mut d = HalfDifference::zeros(1, 1);
        for (from, to) in [(0, 1), (1, 3), (3, 4), (4, 9), (9, 9), (9, 16), (16, 17)] {
            d.count(from, to);
        }
        assert_eq!(d.counts, [9, 8]);
    }

    #[test]
    fn alpha_is_unmeasured_without_noise_or_a_half_and_clamped() {
        let (d, sums) = render(8, 8, 1, 0.1, 0.1);
        assert_eq!(d.alpha([&sums[0], &sums[1], &sums[2]]), None, "one sample: no odd half");
        let (mut d, sums) = render(8, 8, 4, 0.0, 0.0);
        assert_eq!(d.alpha([&sums[0], &sums[1], &sums[2]]), None, "no noise at all");
        d.dx[0] += 1.0;
        assert_eq!(d.alpha([&sums[0], &sums[1], &sums[2]]), None, "a noise-free primal: no ratio");
        // gradients far noisier than the primal: every difference capped, α ≈ the cap, clamped
        let (d, sums) = render(8, 8, 4, 1e-4, 10.0);
        assert_eq!(d.alpha([&sums[0], &sums[1], &sums[2]]), Some(ALPHA_RANGE.1));
        let (d, sums) = render(8, 8, 4, 10.0, 1e-4);
        assert_eq!(d.alpha([&sums[0], &sums[1], &sums[2]]), Some(ALPHA_RANGE.0));
        let (d, sums) = render(1, 400, 8, 0.1, 0.05);
        let a = d.alpha([&sums[0], &sums[1], &sums[2]]).unwrap();
        assert!((a / 0.5 - 1.0).abs() < 0.1, "one column (no dx exists): α = {a}");
    }
}
