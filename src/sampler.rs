//! Streams of primary samples in [0,1). Every path is built by asking one `Sampler` for its
//! numbers in a fixed order, so that the Metropolis samplers can drive the same path builder
//! by replacing this stream with a mutated primary-sample vector.

use glam::Vec2;
use rand_core::Rng;
use rand_pcg::Pcg32;

/// The one interface through which the path builder draws its random numbers.
pub trait Sampler {
    /// The next primary sample coordinate, uniform in [0,1).
    fn next_1d(&mut self) -> f32;
    #[inline]
    fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        Vec2::new(x, self.next_1d())
    }
}

/// SplitMix64 finaliser: decorrelates seeds built from (seed, pixel, sample) tuples.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Converts 32 random bits to a float uniform in [0,1) (24 bits of mantissa: never 1.0).
#[inline]
pub fn u32_to_unit_f32(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// Independent uniform samples from PCG32 (O'Neill 2014).
#[derive(Clone, Debug)]
pub struct IndependentSampler {
    rng: Pcg32,
}

impl IndependentSampler {
    /// A stream determined only by its arguments: renders are reproducible for a seed,
    /// whatever the thread count or scheduling.
    pub fn new(seed: u64, stream: u64) -> Self {
        let state = mix64(seed ^ mix64(stream));
        IndependentSampler { rng: Pcg32::new(state, mix64(stream.wrapping_add(0x5851_F42D))) }
    }
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        self.rng.next_u32()
    }
}

impl Sampler for IndependentSampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        u32_to_unit_f32(self.rng.next_u32())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_moments() {
        let mut s = IndependentSampler::new(7, 3);
        let n = 200_000;
        let (mut m1, mut m2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let x = s.next_1d() as f64;
            assert!((0.0..1.0).contains(&x));
            m1 += x;
            m2 += x * x;
        }
        m1 /= n as f64;
        m2 /= n as f64;
        // mean 1/2 (σ of the mean = 0.29/sqrt(n) ≈ 6.5e-4), E[x²] = 1/3.
        assert!((m1 - 0.5).abs() < 4e-3, "{m1}");
        assert!((m2 - 1.0 / 3.0).abs() < 4e-3, "{m2}");
    }

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u32> = (0..8)
            .map({
                let mut s = IndependentSampler::new(1, 2);
                move |_| s.next_u32()
            })
            .collect();
        let b: Vec<u32> = (0..8)
            .map({
                let mut s = IndependentSampler::new(1, 2);
                move |_| s.next_u32()
            })
            .collect();
        let c: Vec<u32> = (0..8)
            .map({
                let mut s = IndependentSampler::new(1, 3);
                move |_| s.next_u32()
            })
            .collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
