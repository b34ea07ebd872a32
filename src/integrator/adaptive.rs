//! Adaptive sampling for `pt` (Blender's "Noise Threshold"; the per-pixel error of Dammertz
//! et al. 2010, "A Hierarchical Automatic Stopping Condition for Monte Carlo Global
//! Illumination", §2.1, as Cycles uses it): pixels whose estimate has settled stop taking
//! samples, and the rest of the budget goes to the pixels that are still noisy.
//!
//! Each pixel keeps, beside the sum I of its n samples, the sum A of its odd-numbered
//! samples (the 2nd, 4th, …), an estimate of the same mean from half of them. At each check
//! its error is
//!
//!   e = Σ_rgb |I/n − A/⌊n/2⌋| / (10⁻⁴ + s),   b = (I_r + I_g + I_b)/n,  s = √b if b < 1, else b,
//!
//! the difference of the two estimates relative to the square root of the pixel's
//! brightness (so a dark pixel is not held to the noise of a bright one, and noise matters
//! about as the eye sees it). A pixel has converged when e < threshold. The pixels that keep
//! sampling are those within one pixel (3×3) of a pixel that has not converged, so that the
//! edge of a noisy region is not frozen beside it (Cycles' dilation).
//!
//! Checks happen once every pixel has `min_samples`, then every `STEP` samples. Parameters:
//! `threshold` (the render setting `adaptive_threshold`; 0 = off, Blender's default 0.01)
//! and `min_samples` (`adaptive_min_samples`; 0 = automatic: max(4, ⌈16 / threshold^0.3⌉),
//! 64 at 0.01, as Cycles). The image stays each pixel's mean of its own samples; which pixels
//! stop depends only on the film, so the result is the same for any thread count.

use crate::film::Film;

/// Samples between two convergence checks (a power of two: checks fall on even counts, so
/// the half buffer holds exactly half of every checked pixel's samples).
pub const STEP: u32 = 16;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveSampling {
    pub threshold: f32,
    pub min_samples: u32,
}

impl AdaptiveSampling {
    /// None when adaptive sampling is off (threshold 0).
    pub fn new(threshold: f32, min_samples: u32) -> Option<AdaptiveSampling> {
        (threshold > 0.0).then(|| AdaptiveSampling {
            threshold,
            min_samples: if min_samples == 0 { Self::automatic_min_samples(threshold) } else { min_samples.max(4) },
        })
    }

    /// max(4, ⌈16 / threshold^0.3⌉): 32 at 0.1, 64 at 0.01, 128 at 0.001.
    pub fn automatic_min_samples(threshold: f32) -> u32 {
        ((16.0 / threshold.powf(0.3)).ceil() as u32).max(4)
    }

    /// Whether the pixels are checked after `done` samples.
    pub fn checks_at(&self, done: u32) -> bool {
        done >= self.min_samples && done.is_multiple_of(STEP)
    }

    /// Where a pass that would run from `done` to `to` ends: at the next check if it comes
    /// first.
    pub fn pass_end(&self, done: u32, to: u32) -> u32 {
        let next =
            if done < self.min_samples { self.min_samples.next_multiple_of(STEP) } else { (done / STEP + 1) * STEP };
        to.min(next)
    }
}

/// A pixel's error from the sum of its samples, the sum of its odd-numbered ones and its
/// sample count (infinite below 2 samples: nothing to compare).
pub fn pixel_error(sum: [f32; 3], half: [f32; 3], n: u32) -> f32 {
    let n_half = n / 2;
    if n_half == 0 {
        return f32::INFINITY;
    }
    let (inv, inv_half) = (1.0 / n as f32, 1.0 / n_half as f32);
    let diff: f32 = (0..3).map(|c| (sum[c] * inv - half[c] * inv_half).abs()).sum();
    let intensity = (sum[0] + sum[1] + sum[2]) * inv;
    let scale = if intensity < 1.0 { intensity.max(0.0).sqrt() } else { intensity };
    diff / (1e-4 + scale)
}

/// Marks the film's pixels that go on sampling (those within one pixel of one whose error
/// is at or above `threshold`); returns how many they are.
pub fn update_active(film: &mut Film, threshold: f32) -> usize {
    let (w, h) = (film.width, film.height);
    let noisy: Vec<bool> = film
        .rows
        .iter()
        .flat_map(|r| (0..w).map(move |x| !(pixel_error(r.color[x], r.half[x], r.count[x]) < threshold)))
        .collect();
    // dilate along x, then along y
    let mut along_x = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            along_x[y * w + x] = (x.saturating_sub(1)..=(x + 1).min(w - 1)).any(|i| noisy[y * w + i]);
        }
    }
    let mut n = 0;
    for (y, row) in film.rows.iter_mut().enumerate() {
        for x in 0..w {
            let a = (y.saturating_sub(1)..=(y + 1).min(h - 1)).any(|j| along_x[j * w + x]);
            row.active[x] = a;
            n += a as usize;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn automatic_minimum_samples_follow_the_threshold() {
        assert_eq!(AdaptiveSampling::automatic_min_samples(0.1), 32);
        assert_eq!(AdaptiveSampling::automatic_min_samples(0.01), 64);
        assert_eq!(AdaptiveSampling::automatic_min_samples(0.001), 128);
        assert!(AdaptiveSampling::new(0.0, 0).is_none());
        assert_eq!(AdaptiveSampling::new(0.01, 2).unwrap().min_samples, 4);
    }

    #[test]
    fn passes_end_at_the_checks() {
        let a = AdaptiveSampling::new(0.01, 0).unwrap(); // min 64
        assert_eq!(a.pass_end(0, 100), 64);
        assert_eq!(a.pass_end(32, 40), 40);
        assert_eq!(a.pass_end(64, 1000), 80);
        assert_eq!(a.pass_end(70, 1000), 80);
        assert!(a.checks_at(64) && a.checks_at(80) && !a.checks_at(48) && !a.checks_at(70));
        let odd = AdaptiveSampling::new(0.01, 10).unwrap();
        assert_eq!(odd.pass_end(0, 100), 16);
        assert!(odd.checks_at(16) && !odd.checks_at(10));
    }

    /// The error is the two estimates' difference relative to √brightness (below 1) or the
    /// brightness itself (above), and 0 when both halves agree.
    #[test]
    fn pixel_error_compares_the_half_estimate_with_the_whole() {
        // 4 samples of a grey 0.25: I = 1 per channel, A (2 samples) = 0.5
        assert_eq!(pixel_error([1.0; 3], [0.5; 3], 4), 0.0);
        // means 0.25 vs 0.3 per channel: |diff| 0.05 × 3 over √0.75
        let e = pixel_error([1.0; 3], [0.6; 3], 4);
        assert!((e - 0.15 / (1e-4 + 0.75f32.sqrt())).abs() < 1e-6, "{e}");
        // bright: means 2.5 vs 3 in red only, brightness 7.5 → relative to 7.5
        let e = pixel_error([10.0, 10.0, 10.0], [6.0, 5.0, 5.0], 4);
        assert!((e - 0.5 / (1e-4 + 7.5)).abs() < 1e-6, "{e}");
        assert_eq!(pixel_error([1.0; 3], [0.0; 3], 1), f32::INFINITY);
    }

    /// One noisy pixel keeps its 3×3 neighbourhood sampling and nothing else.
    #[test]
    fn a_noisy_pixel_keeps_its_neighbours_sampling() {
        let mut film = Film::new(6, 5);
        film.enable_adaptive();
        for row in &mut film.rows {
            for x in 0..6 {
                (row.color[x], row.half[x], row.count[x]) = ([2.0; 3], [1.0; 3], 8);
            }
        }
        film.rows[2].half[4] = [3.0; 3]; // pixel (4, 2) disagrees with itself
        assert_eq!(update_active(&mut film, 0.01), 9);
        for (y, row) in film.rows.iter().enumerate() {
            for x in 0..6 {
                let near = (3..=5).contains(&x) && (1..=3).contains(&y);
                assert_eq!(row.active[x], near, "pixel ({x}, {y})");
            }
        }
        // at a corner the neighbourhood is cut by the image's edge
        film.rows[2].half[4] = [1.0; 3];
        film.rows[0].half[0] = [3.0; 3];
        assert_eq!(update_active(&mut film, 0.01), 4);
        assert!(film.rows[1].active[1] && !film.rows[2].active[0] && !film.rows[0].active[2]);
    }
}
