//! Owen-scrambled 4-D Sobol points with a shuffled index (Burley 2020, "Practical Hash-based
//! Owen Scrambling"). Sobol points are linear in the index's bits over GF(2), so a point is
//! the xor of two table entries, one for the index's low byte and one for its high byte
//! (two 4 KB tables, in L1 cache), instead of a matrix–vector product per point.
//!
//! - Sobol dimensions 0–3 (Joe & Kuo 2008 direction numbers: van der Corput; x + 1;
//!   x² + x + 1 with m = 1, 3; x³ + x + 1 with m = 1, 3, 1), natural (not Gray-code) order.
//! - The index is shuffled by an Owen scramble of its 16 bits (`shuffle_index`), so the first
//!   2^k shuffled indices form one aligned block of 2^k indices, which Sobol stratifies as it
//!   does its first 2^k: each power-of-two prefix keeps its stratification, and sets drawn
//!   with different seeds are decorrelated.
//! - Each coordinate is Owen-scrambled (`owen_scramble`): every bit flipped by a hash of the
//!   bits above it, a bijection that keeps every elementary interval's count.
//!
//! The hash is Laine and Karras' (2011) multiply–xor construction with the constants of
//! pbrt-v4's fast Owen scrambler: each step changes a bit by the bits below it only.
//! Why: the `sobol_burley` crate's `sample_4d` (42 ns a 4-D point, x86-64-v3) took a fifth
//! of a path tracer's time (perf, 128² lights scene). Measured in renders (old and new core
//! in one process, in turn, 2026-12-03): `pt` 64 spp on the lights scene 0.527 → 0.469 s
//! (min of 8; median 0.552 → 0.494), `gdpt` 32 spp on the Cornell box 0.607 → 0.552 s (min of
//! 6; median 0.651 → 0.631). A single 1 MB table of all 2^16 points was 20 ns a point alone
//! but no faster in a render, where its lookups missed the cache.
//! The sampler evaluates in the bit-reversed domain (`sample_4d_reversed`, equal bit for bit):
//! its index reversed once, tables of reversed entries at reversed bytes, so a 4-D set costs 4
//! bit reversals instead of 10 (x86-64 has no reversal instruction). Cornell box 256², 7 runs,
//! old and new core in turn (2026-12-05): `pt` 64 spp 1.449 → 1.355 s (min; median 1.465 →
//! 1.379), `gdpt` 16 spp 0.950 → 0.924 s (median 1.149 → 0.937).

/// The keys of the four coordinates' scrambles (with the set's seed).
const LANES: [u32; 4] = [0x912f_69ba, 0x174f_18ab, 0x691e_72ca, 0xb40c_c1b8];

/// The largest sample index + 1 a 4-D set serves.
pub const TABLE_SIZE: u32 = 1 << 16;

/// Direction numbers v[d][k] (32-bit, most significant bit first) of dimensions 0–3 for index
/// bits k < 16.
const fn direction_numbers() -> [[u32; 16]; 4] {
    // (degree s, coefficients a, initial m_1..m_s) of each dimension's primitive polynomial
    const S: [usize; 3] = [1, 2, 3];
    const A: [u32; 3] = [0, 1, 1];
    const M: [[u32; 3]; 3] = [[1, 0, 0], [1, 3, 0], [1, 3, 1]];
    let mut v = [[0u32; 16]; 4];
    let mut k = 0;
    while k < 16 {
        v[0][k] = 1 << (31 - k);
        k += 1;
    }
    let mut d = 0;
    while d < 3 {
        let s = S[d];
        let mut k = 0;
        while k < 16 {
            v[d + 1][k] = if k < s {
                M[d][k] << (31 - k)
            } else {
                let mut x = v[d + 1][k - s] ^ (v[d + 1][k - s] >> s);
                let mut j = 1;
                while j < s {
                    if (A[d] >> (s - 1 - j)) & 1 == 1 {
                        x ^= v[d + 1][k - j];
                    }
                    j += 1;
                }
                x
            };
            k += 1;
        }
        d += 1;
    }
    v
}

/// BYTES[h][b]: the xor of the direction numbers of the set bits of byte b, as the index's
/// low (h = 0) or high (h = 1) byte.
static BYTES: [[[u32; 4]; 256]; 2] = {
    let v = direction_numbers();
    let mut t = [[[0u32; 4]; 256]; 2];
    let mut h = 0;
    while h < 2 {
        let mut b = 0;
        while b < 256 {
            let mut d = 0;
            while d < 4 {
                let mut x = 0u32;
                let mut k = 0;
                while k < 8 {
                    if (b >> k) & 1 == 1 {
                        x ^= v[d][8 * h + k];
                    }
                    k += 1;
                }
                t[h][b][d] = x;
                d += 1;
            }
            b += 1;
        }
        h += 1;
    }
    t
};

/// REVERSED[h][x]: the bit-reversed entries of BYTES[h] at the bit-reversed byte x — what
/// `sample_4d_reversed` looks up with the index shuffle's hash before its bits are turned
/// back (reversal is linear over xor, so the point's reversed coordinates are the xor of
/// these, and the Owen scramble's first reversal is already done).
static REVERSED: [[[u32; 4]; 256]; 2] = {
    let mut t = [[[0u32; 4]; 256]; 2];
    let mut h = 0;
    while h < 2 {
        let mut x = 0;
        while x < 256 {
            let b = (x as u8).reverse_bits() as usize;
            let mut d = 0;
            while d < 4 {
                t[h][x][d] = BYTES[h][b][d].reverse_bits();
                d += 1;
            }
            x += 1;
        }
        h += 1;
    }
    t
};

/// Point `index` (< `TABLE_SIZE`) of Sobol's dimensions 0–3, as 32-bit fractions.
#[inline]
fn sobol4(index: u32) -> [u32; 4] {
    let (lo, hi) = (&BYTES[0][(index & 0xff) as usize], &BYTES[1][((index >> 8) & 0xff) as usize]);
    std::array::from_fn(|d| lo[d] ^ hi[d])
}

/// Laine–Karras hash of `v` keyed by `seed`: each output bit depends on the input bits at
/// and below it (and the seed), and it is a bijection.
#[inline]
fn lk_hash(mut v: u32, seed: u32) -> u32 {
    v ^= v.wrapping_mul(0x3d20_adea);
    v = v.wrapping_add(seed);
    v = v.wrapping_mul((seed >> 16) | 1);
    v ^= v.wrapping_mul(0x0552_6c56);
    v ^= v.wrapping_mul(0x53a2_2864);
    v
}

/// A 32-bit integer hash (for seeds).
#[inline]
pub fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

/// Owen scramble of a 16-bit sample index: a permutation that maps each aligned block of
/// 2^k indices onto an aligned block of 2^k.
#[inline]
pub fn shuffle_index(index: u32, seed: u32) -> u32 {
    owen_scramble(index << 16, seed) >> 16
}

/// Owen scramble of a 32-bit fraction: each bit flipped by a hash of the bits above it.
#[inline]
pub fn owen_scramble(v: u32, seed: u32) -> u32 {
    lk_hash(v.reverse_bits(), seed).reverse_bits()
}

/// `sample_4d` from `(index << 16).reverse_bits()` (a sampler's index, reversed once): the
/// same values with 4 bit reversals instead of 10. The shuffle's hash h gives the shuffled
/// index's bytes reversed (its low byte is h's second byte turned round, its high byte h's
/// first), which index `REVERSED` directly.
#[inline]
pub fn sample_4d_reversed(index_reversed: u32, seed: u32) -> [f32; 4] {
    let h = lk_hash(index_reversed, hash(seed ^ 0x79c6_8e4a));
    let (lo, hi) = (&REVERSED[0][((h >> 8) & 0xff) as usize], &REVERSED[1][(h & 0xff) as usize]);
    let s = seed.wrapping_mul(0x9c8f_2d3b);
    std::array::from_fn(|d| crate::sampler::u32_to_unit_f32(lk_hash(lo[d] ^ hi[d], hash(s ^ LANES[d])).reverse_bits()))
}

/// Point `index` (< `TABLE_SIZE`) of the 4-D sequence keyed by `seed`, in [0,1)^4.
#[inline]
pub fn sample_4d(index: u32, seed: u32) -> [f32; 4] {
    let p = sobol4(shuffle_index(index, hash(seed ^ 0x79c6_8e4a)));
    let s = seed.wrapping_mul(0x9c8f_2d3b);
    std::array::from_fn(|d| crate::sampler::u32_to_unit_f32(owen_scramble(p[d], hash(s ^ LANES[d]))))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reversed-domain evaluation is the reference one, bit for bit.
    #[test]
    fn reversed_sampling_is_sample_4d() {
        for index in (0..TABLE_SIZE).step_by(97).chain([0, 1, 255, 256, TABLE_SIZE - 1]) {
            for seed in [0u32, 1, 0xdead_beef, 0x1234_5678] {
                assert_eq!(
                    sample_4d_reversed((index << 16).reverse_bits(), seed),
                    sample_4d(index, seed),
                    "{index} {seed}"
                );
            }
        }
    }

    /// The first 2^m points of each dimension hit every interval of width 2^−m once, and
    /// dimensions 0 and 1 form a (0, 2)-sequence: every elementary interval of area 2^−8
    /// (2^−i × 2^−(8−i)) holds one of the first 256 points, and of each aligned block of 256.
    #[test]
    fn the_tables_give_sobol() {
        let t: Vec<[u32; 4]> = (0..TABLE_SIZE).map(sobol4).collect();
        for d in 0..4 {
            let mut seen = vec![false; TABLE_SIZE as usize];
            for p in &t {
                let k = (p[d] >> 16) as usize;
                assert!(!seen[k], "dimension {d}: two points in interval {k}");
                seen[k] = true;
            }
        }
        for block in [0usize, 256 * 37, 65_536 - 256] {
            for i in 0..=8u32 {
                let mut count = vec![0; 256];
                for p in &t[block..block + 256] {
                    let (x, y) = (p[0].checked_shr(32 - i).unwrap_or(0), p[1].checked_shr(24 + i).unwrap_or(0));
                    count[((x << (8 - i)) | y) as usize] += 1;
                }
                assert!(count.iter().all(|&c| c == 1), "block {block}, intervals 2^-{i} × 2^-{}", 8 - i);
            }
        }
        // the known start of Sobol's dimensions 1–3 (natural order)
        let f = |k: usize, d: usize| t[k][d] as f64 / 4_294_967_296.0;
        assert_eq!([f(1, 1), f(2, 1), f(3, 1), f(4, 2), f(5, 3)], [0.5, 0.75, 0.25, 0.375, 0.625]);
    }

    /// The index shuffle is a permutation of the 16-bit indices that maps the first 2^k onto
    /// one aligned block of 2^k (so each power-of-two prefix stays stratified); the Owen scramble
    /// is a bijection on the top bits: the first 2^k scrambled points still hit every interval
    /// of width 2^−k once.
    #[test]
    fn scrambles_are_permutations_that_keep_strata() {
        for seed in [0u32, 1, 0xdead_beef] {
            let mut seen = vec![false; TABLE_SIZE as usize];
            for i in 0..TABLE_SIZE {
                let j = shuffle_index(i, hash(seed)) as usize;
                assert!(!seen[j]);
                seen[j] = true;
            }
            for k in [4u32, 8, 12] {
                let mut low = vec![false; 1 << k];
                let block = shuffle_index(0, hash(seed)) >> k;
                for i in 0..1u32 << k {
                    let j = shuffle_index(i, hash(seed));
                    assert_eq!(j >> k, block, "seed {seed}: prefix 2^{k} leaves its block");
                    let j = (j & ((1 << k) - 1)) as usize;
                    assert!(!low[j], "seed {seed}: prefix 2^{k} repeats low bits {j}");
                    low[j] = true;
                }
                for d in 0..4 {
                    let mut hit = vec![false; 1 << k];
                    for i in 0..1u32 << k {
                        let x = (sample_4d(i, seed)[d] * (1u32 << k) as f32) as usize;
                        assert!(!hit[x], "seed {seed}, dimension {d}: prefix 2^{k} hits interval {x} twice");
                        hit[x] = true;
                    }
                }
            }
        }
        // dimensions 0 and 1 scrambled: still a (0, 2)-sequence in its first 256 points
        for seed in [5u32, 77] {
            for i in 0..=8u32 {
                let mut count = vec![0; 256];
                for n in 0..256 {
                    let p = sample_4d(n, seed);
                    let (x, y) = ((p[0] * (1u32 << i) as f32) as usize, (p[1] * (1u32 << (8 - i)) as f32) as usize);
                    count[(x << (8 - i)) | y] += 1;
                }
                assert!(count.iter().all(|&c| c == 1), "seed {seed}: intervals 2^-{i} × 2^-{}", 8 - i);
            }
        }
        assert_ne!(sample_4d(3, 1), sample_4d(3, 2));
    }
}
