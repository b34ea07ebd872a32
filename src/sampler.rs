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

/// Dimensions a pixel sample draws before its path: the position in the pixel (2), then the
/// path's lens sample (2). The path builder then draws `path::SAMPLES_PER_VERTEX` per vertex.
pub const PIXEL_DIMENSIONS: u32 = 4;

/// Owen-scrambled Sobol points (Burley 2020, `crate::sobol`; Cycles' pattern family),
/// "padded": the stream is cut into 4-D sets, each its own independently shuffled
/// and scrambled 4-D Sobol sequence over the pixel's samples, so each set is stratified
/// whatever the others do. The sets follow what the path builder draws: {pixel position,
/// lens}, then per vertex {light choice, light point (2), lobe} and {BSDF direction (2),
/// roulette, free-flight distance}, so every 2-D pair it uses lies inside one set. Sample indices past
/// 2^16 (the table's size) draw independent numbers instead.
#[derive(Clone, Debug)]
pub struct SobolSampler {
    /// The sample's index, bit-reversed once (`sobol::sample_4d_reversed`).
    index_reversed: u32,
    seed: u32,
    /// The next dimension's component in the current set (`layout`, followed incrementally).
    in_set: u32,
    set: u32,
    cache: [f32; 4],
    fallback: Option<IndependentSampler>,
    /// Every even set after set 0 is 3 dimensions long (`for_subpaths`), not 4.
    short_even_sets: bool,
}

impl SobolSampler {
    /// Sample `index` of the pixel whose stream is `stream` (seed and pixel mixed in).
    pub fn new(seed: u64, stream: u64, index: u32) -> Self {
        let fallback =
            (index >= crate::sobol::TABLE_SIZE).then(|| IndependentSampler::new(seed, stream ^ ((index as u64) << 40)));
        SobolSampler {
            index_reversed: (index << 16).reverse_bits(),
            seed: mix64(seed ^ mix64(stream)) as u32,
            in_set: 4,
            set: u32::MAX,
            cache: [0.0; 4],
            fallback,
            short_even_sets: false,
        }
    }

    /// The stream `bdpt` draws its subpaths from: the sets of the path builder's layout
    /// before its free-flight dimension (every even set after set 0 three dimensions long),
    /// which bdpt's tests and measurements were made with.
    pub fn for_subpaths(seed: u64, stream: u64, index: u32) -> Self {
        SobolSampler { short_even_sets: true, ..Self::new(seed, stream, index) }
    }

    /// The 4-D set and its component that dimension `d` of the stream falls in (`next_1d`
    /// follows it incrementally; the tests check the two agree).
    #[cfg_attr(not(test), allow(dead_code))]
    fn layout(d: u32) -> (u32, usize) {
        if d < PIXEL_DIMENSIONS {
            return (0, d as usize);
        }
        let per_vertex = crate::path::SAMPLES_PER_VERTEX as u32;
        let (v, r) = ((d - PIXEL_DIMENSIONS) / per_vertex, (d - PIXEL_DIMENSIONS) % per_vertex);
        (1 + 2 * v + u32::from(r >= 4), (r % 4) as usize)
    }
}

impl Sampler for SobolSampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        if let Some(f) = &mut self.fallback {
            return f.next_1d();
        }
        // `layout` followed incrementally: the sets come in order, each 4 dimensions long
        // (`for_subpaths`: every even set after set 0 is 3)
        let mut k = self.in_set;
        let len = if self.short_even_sets && self.set != 0 && self.set.is_multiple_of(2) { 3 } else { 4 };
        if k >= len {
            let set = self.set.wrapping_add(1);
            let set_seed = mix64(((self.seed as u64) << 32) | set as u64) as u32;
            self.cache = crate::sobol::sample_4d_reversed(self.index_reversed, set_seed);
            self.set = set;
            k = 0;
        }
        self.in_set = k + 1;
        self.cache[k as usize].min(1.0 - f32::EPSILON / 2.0)
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

/// Primary-sample-space state for Metropolis light transport (Kelemen et al. 2002, with
/// pbrt-v3's lazy evaluation): coordinates are created and mutated only when the path
/// builder asks for them, and restored on rejection.
#[derive(Clone, Debug)]
pub struct PssSampler {
    rng: IndependentSampler,
    x: Vec<PrimarySample>,
    index: usize,
    iteration: u64,
    last_large_step: u64,
    large_step: bool,
    sigma: f32,
    large_step_probability: f32,
}

#[derive(Clone, Copy, Debug, Default)]
struct PrimarySample {
    value: f32,
    modified: u64,
    backup_value: f32,
    backup_modified: u64,
}

/// Standard deviation of a small step per coordinate (pbrt's default).
pub const SMALL_STEP_SIGMA: f32 = 0.01;

impl PssSampler {
    pub fn new(seed: u64, stream: u64, large_step_probability: f32) -> Self {
        PssSampler { x: Vec::with_capacity(64), ..Self::new_empty(seed, stream, large_step_probability) }
    }

    /// Starts a proposal: a large step (all coordinates redrawn) with the configured
    /// probability, else a small step. The first iteration is always a large step.
    pub fn start_iteration(&mut self) {
        self.iteration += 1;
        self.large_step = self.iteration == 1 || self.rng.next_1d() < self.large_step_probability;
        self.index = 0;
    }

    pub fn is_large_step(&self) -> bool {
        self.large_step
    }

    pub fn accept(&mut self) {
        if self.large_step {
            self.last_large_step = self.iteration;
        }
    }

    pub fn reject(&mut self) {
        for xi in &mut self.x {
            if xi.modified == self.iteration {
                xi.value = xi.backup_value;
                xi.modified = xi.backup_modified;
            }
        }
        self.iteration -= 1;
    }

    /// Gives the state a new random stream (keeping its coordinates): chains that start from
    /// the same bootstrap state must not then make the same proposals.
    /// The sampler `new(seed, stream, p)` would make, reusing this one's storage (the
    /// bootstrap restarts one sampler per thread instead of allocating one per sample).
    pub fn restart(&mut self, seed: u64, stream: u64) {
        let mut x = std::mem::take(&mut self.x);
        x.clear();
        *self = PssSampler { x, ..PssSampler::new_empty(seed, stream, self.large_step_probability) };
    }

    fn new_empty(seed: u64, stream: u64, large_step_probability: f32) -> Self {
        PssSampler {
            rng: IndependentSampler::new(seed, stream),
            x: Vec::new(),
            index: 0,
            iteration: 0,
            last_large_step: 0,
            large_step: true,
            sigma: SMALL_STEP_SIGMA,
            large_step_probability,
        }
    }

    pub fn reseed(&mut self, seed: u64, stream: u64) {
        self.rng = IndependentSampler::new(seed, stream);
    }

    /// The chain's own random numbers (acceptance tests, discrete mutations).
    pub fn rng(&mut self) -> &mut IndependentSampler {
        &mut self.rng
    }

    fn gaussian(&mut self) -> f32 {
        // Box–Muller
        let u1 = self.rng.next_1d().max(1e-12);
        let u2 = self.rng.next_1d();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f32::consts::PI * u2).cos()
    }

    fn ensure_ready(&mut self, i: usize) {
        if i >= self.x.len() {
            self.x.resize(i + 1, PrimarySample::default());
        }
        let mut xi = self.x[i];
        // Apply the large step that this coordinate missed.
        if xi.modified < self.last_large_step {
            xi.value = self.rng.next_1d();
            xi.modified = self.last_large_step;
        }
        xi.backup_value = xi.value;
        xi.backup_modified = xi.modified;
        if self.large_step {
            xi.value = self.rng.next_1d();
        } else {
            // The small steps it missed compose into one Gaussian of σ·√n.
            let n = (self.iteration - xi.modified) as f32;
            let step = self.gaussian() * self.sigma * n.sqrt();
            xi.value += step;
            xi.value -= xi.value.floor();
            if xi.value >= 1.0 {
                xi.value = 0.0;
            }
        }
        xi.modified = self.iteration;
        self.x[i] = xi;
    }
}

impl Sampler for PssSampler {
    #[inline]
    fn next_1d(&mut self) -> f32 {
        let i = self.index;
        self.index += 1;
        self.ensure_ready(i);
        self.x[i].value
    }
}

#[cfg(test)]
mod pss_tests {
    use super::*;

    #[test]
    fn reject_restores_the_state() {
        let mut s = PssSampler::new(1, 2, 0.3);
        s.start_iteration();
        let a: Vec<f32> = (0..5).map(|_| s.next_1d()).collect();
        s.accept();
        for _ in 0..20 {
            s.start_iteration();
            let _b: Vec<f32> = (0..5).map(|_| s.next_1d()).collect();
            s.reject();
        }
        // a lazily-updated coordinate read after rejections still equals its accepted value
        // when the next step is forced small and σ→0 (checked here by replaying the state)
        let mut t = s.clone();
        t.sigma = 0.0;
        t.large_step_probability = 0.0;
        t.start_iteration();
        let c: Vec<f32> = (0..5).map(|_| t.next_1d()).collect();
        assert_eq!(a, c);
    }

    /// Small steps are symmetric and stay in [0,1): the chain over one coordinate with
    /// target ≡ 1 accepts everything and must stay uniform.
    #[test]
    fn uniform_target_stays_uniform() {
        let mut s = PssSampler::new(3, 4, 0.3);
        let mut hist = [0usize; 10];
        let n = 200_000;
        for _ in 0..n {
            s.start_iteration();
            let v = s.next_1d();
            assert!((0.0..1.0).contains(&v));
            s.accept();
            hist[(v * 10.0) as usize] += 1;
        }
        for h in hist {
            let p = h as f64 / n as f64;
            assert!((p - 0.1).abs() < 0.01, "{hist:?}");
        }
    }

    /// `next_1d` walks the sets as `layout` defines them: dimension d is component
    /// layout(d).1 of set layout(d).0's point, for the first 100 dimensions of many samples.
    #[test]
    fn sobol_stream_follows_its_layout() {
        for i in [0u32, 1, 5, 77, 4095] {
            let mut s = SobolSampler::new(3, 9, i);
            let seed = s.seed;
            for d in 0..100 {
                let (set, k) = SobolSampler::layout(d);
                let set_seed = mix64(((seed as u64) << 32) | set as u64) as u32;
                let want = crate::sobol::sample_4d_reversed((i << 16).reverse_bits(), set_seed)[k];
                assert_eq!(s.next_1d(), want.min(1.0 - f32::EPSILON / 2.0), "sample {i}, dimension {d}");
            }
        }
    }

    /// The Sobol sampler's first 2-D pairs are stratified over a pixel's samples: with 2^k
    /// samples every one of the 2^k elementary intervals of each pair's 1-D projections holds
    /// exactly one point, and the 2-D pair (pixel position) fills a 16×16 grid of 256 points
    /// one per cell in each row and column (a (0,2)-net's projections); the stream's numbers
    /// lie in [0,1) and a pair split across sets never happens for the layout's pairs.
    #[test]
    fn sobol_points_are_stratified_in_every_pair_the_path_builder_uses() {
        let n = 256u32;
        let per_vertex = crate::path::SAMPLES_PER_VERTEX as u32;
        // the pairs: pixel position, lens, and per vertex light point and BSDF direction
        let mut pairs = vec![(0u32, 1u32), (2, 3)];
        for v in 0..4 {
            let base = PIXEL_DIMENSIONS + v * per_vertex;
            pairs.push((base + 1, base + 2));
            pairs.push((base + 4, base + 5));
        }
        for &(a, b) in &pairs {
            assert_eq!(SobolSampler::layout(a).0, SobolSampler::layout(b).0, "pair ({a}, {b}) split across sets");
        }
        let dims = PIXEL_DIMENSIONS + 4 * per_vertex;
        let points: Vec<Vec<f32>> = (0..n)
            .map(|i| {
                let mut s = SobolSampler::new(7, 42, i);
                (0..dims).map(|_| s.next_1d()).collect()
            })
            .collect();
        for &(a, b) in &pairs {
            let (mut rows, mut cols) = (vec![0; 16], vec![0; 16]);
            let mut strata_a = vec![0; n as usize];
            for p in &points {
                let (x, y) = (p[a as usize], p[b as usize]);
                assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                strata_a[(x * n as f32) as usize] += 1;
                rows[(x * 16.0) as usize] += 1;
                cols[(y * 16.0) as usize] += 1;
            }
            assert!(strata_a.iter().all(|&c| c == 1), "dimension {a}: not one point per 1/{n} interval");
            assert!(rows.iter().chain(&cols).all(|&c| c == 16), "pair ({a}, {b}): rows {rows:?} cols {cols:?}");
        }
        // different pixels are scrambled differently
        assert_ne!(SobolSampler::new(7, 1, 0).next_1d(), SobolSampler::new(7, 2, 0).next_1d());
        // past the crate's limit: independent numbers, still in [0,1)
        let mut far = SobolSampler::new(7, 1, 1 << 16);
        assert!((0..100).map(|_| far.next_1d()).all(|x| (0.0..1.0).contains(&x)));
    }
}
