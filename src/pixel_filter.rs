//! The pixel filter: where inside (and around) its pixel a camera sample is taken. Filter
//! importance sampling: the sample's offset from the pixel centre is drawn from the filter,
//! so every sample has weight 1 and each pixel estimates the image convolved with the filter.
//! Separable, as Cycles samples it (x and y each from the 1D filter). Every method takes
//! its camera samples through it (the Metropolis chains map the fraction of their pixel
//! coordinate, integrator/mlt.rs).
//!
//! Parameters (the scene's camera, `pixel_filter` and `filter_width`; defaults as Cycles'):
//! * `BLACKMAN_HARRIS` (default), width 1.5 pixels: Cycles'
//!   0.35875 − 0.48829 cos 2πt + 0.14128 cos 4πt − 0.01168 cos 6πt, t = x/(2·width) + ½,
//!   |x| ≤ width — Cycles' "width" of this filter is its radius (its table is built over
//!   twice the width; a 1.5-pixel filter reaches 1.5 pixels either side);
//! * `BOX`: uniform over the pixel (width 1, the former behaviour).

/// Cells of the tabulated CDF.
const TABLE: usize = 1024;

#[derive(Clone, Debug)]
pub enum PixelFilter {
    Box,
    /// The window's CDF at TABLE + 1 evenly spaced offsets across its width, and its guide
    /// table: `start[j]` is the cell that u = j/TABLE falls in (Chen & Asau 1974), from which
    /// a sample's cell is a short forward scan instead of a binary search (that search, ten
    /// dependent branches, was 4–5% of a path tracer's time).
    BlackmanHarris {
        width: f32,
        cdf: Vec<f32>,
        start: Vec<u16>,
    },
}

impl PixelFilter {
    /// The Blackman–Harris filter of Cycles' width `width` (support ±width).
    pub fn blackman_harris(width: f32) -> PixelFilter {
        let support = 2.0 * width as f64;
        // the CDF at TABLE + 1 evenly spaced offsets (trapezoid rule on a 16× finer grid);
        // sampling inverts it exactly between them (a piecewise-constant density), so the
        // window's near-zero tails keep their near-zero share
        let fine = 16 * TABLE;
        let f = |i: usize| blackman_harris(support, (i as f64 / fine as f64 - 0.5) * support);
        let mut cdf = vec![0.0f64; TABLE + 1];
        let mut acc = 0.0;
        for i in 1..=fine {
            acc += 0.5 * (f(i) + f(i - 1));
            if i % 16 == 0 {
                cdf[i / 16] = acc;
            }
        }
        let cdf: Vec<f32> = cdf.iter().map(|c| (c / acc) as f32).collect();
        let start = (0..TABLE).map(|j| cell_of(&cdf, j as f32 / TABLE as f32) as u16).collect();
        PixelFilter::BlackmanHarris { width, cdf, start }
    }

    /// The filter named as the scene describes it (`None` for an unknown name).
    pub fn from_name(name: &str, width: f32) -> Option<PixelFilter> {
        match name.to_ascii_uppercase().as_str() {
            "BOX" => Some(PixelFilter::Box),
            "BLACKMAN_HARRIS" | "BLACKMAN-HARRIS" => Some(PixelFilter::blackman_harris(width)),
            _ => None,
        }
    }

    /// The offset from the pixel centre, in pixels, of the sample u ∈ [0, 1).
    #[inline]
    pub fn offset(&self, u: f32) -> f32 {
        match self {
            PixelFilter::Box => u - 0.5,
            PixelFilter::BlackmanHarris { width, cdf, start } => {
                // the cell i with cdf[i] ≤ u < cdf[i + 1], then linear inside it
                let i = guided_cell(cdf, start, u);
                let span = cdf[i + 1] - cdf[i];
                let t = if span > 0.0 { ((u - cdf[i]) / span).clamp(0.0, 1.0) } else { 0.5 };
                ((i as f32 + t) / TABLE as f32 - 0.5) * 2.0 * width
            }
        }
    }

    /// The density (per pixel) of `offset`'s samples at offset x from the pixel centre: what
    /// a light-tracing sample landing at x adds to that pixel, per axis (the filter is
    /// separable). Exactly the density `offset` draws from: the box's 1 over the pixel, the
    /// tabulated window's piecewise-constant density.
    #[inline]
    pub fn density(&self, x: f32) -> f32 {
        match self {
            PixelFilter::Box => {
                if (-0.5..0.5).contains(&x) {
                    1.0
                } else {
                    0.0
                }
            }
            PixelFilter::BlackmanHarris { width, cdf, .. } => {
                let t = (x / (2.0 * width) + 0.5) * TABLE as f32;
                if !(t >= 0.0 && t < TABLE as f32) {
                    return 0.0;
                }
                let i = t as usize;
                (cdf[i + 1] - cdf[i]) * TABLE as f32 / (2.0 * width)
            }
        }
    }

    /// Half the filter's support, in pixels.
    pub fn radius(&self) -> f32 {
        match self {
            PixelFilter::Box => 0.5,
            PixelFilter::BlackmanHarris { width, .. } => *width,
        }
    }
}

/// `cell_of`, by a forward scan from u's guide-table entry.
#[inline]
fn guided_cell(cdf: &[f32], start: &[u16], u: f32) -> usize {
    let mut i = start[((u * TABLE as f32) as usize).min(TABLE - 1)] as usize;
    while i + 1 < TABLE && cdf[i + 1] <= u {
        i += 1;
    }
    i
}

/// The cell i of a CDF table with cdf[i] ≤ u < cdf[i + 1] (clamped to the table's cells).
fn cell_of(cdf: &[f32], u: f32) -> usize {
    cdf.partition_point(|&c| c <= u).clamp(1, TABLE) - 1
}

/// The Blackman–Harris window of total support `width` at offset x (0 outside it); Cycles
/// evaluates it with width = 2 × its filter width.
pub fn blackman_harris(width: f64, x: f64) -> f64 {
    if x.abs() > 0.5 * width {
        return 0.0;
    }
    let t = std::f64::consts::TAU * (x / width + 0.5);
    0.35875 - 0.48829 * t.cos() + 0.14128 * (2.0 * t).cos() - 0.01168 * (3.0 * t).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Chi-square of 200 000 sampled offsets against the window itself (integrated per bin),
    /// 1e-3 level; every offset within the width.
    #[test]
    fn blackman_harris_offsets_follow_the_window() {
        for width in [1.5f32, 2.0, 1.0] {
            let f = PixelFilter::blackman_harris(width);
            let bins = 30;
            let n = 200_000;
            let mut counts = vec![0usize; bins];
            let mut rng = rand_pcg::Pcg32::new(7, 11);
            use rand_core::Rng;
            for _ in 0..n {
                let u = (rng.next_u32() >> 8) as f32 / (1u32 << 24) as f32;
                let x = f.offset(u);
                assert!(x.abs() <= width + 1e-5, "{x}");
                let b = (((x / (2.0 * width) + 0.5) * bins as f32) as usize).min(bins - 1);
                counts[b] += 1;
            }
            let w = 2.0 * width as f64; // the window's support
            let integral = |a: f64, b: f64| {
                let m = 200;
                (0..m)
                    .map(|i| blackman_harris(w, a + (i as f64 + 0.5) * (b - a) / m as f64) * (b - a) / m as f64)
                    .sum::<f64>()
            };
            let total = integral(-0.5 * w, 0.5 * w);
            let mut chi2 = 0.0;
            let mut df = 0;
            for (b, &c) in counts.iter().enumerate() {
                let lo = (b as f64 / bins as f64 - 0.5) * w;
                let e = integral(lo, lo + w / bins as f64) / total * n as f64;
                if e >= 5.0 {
                    chi2 += (c as f64 - e).powi(2) / e;
                    df += 1;
                }
            }
            let crit = crate::test_stats::critical_1e3(df - 1);
            if chi2 >= crit {
                for (b, &c) in counts.iter().enumerate() {
                    let lo = (b as f64 / bins as f64 - 0.5) * w;
                    eprintln!("bin {b}: {c} vs {}", integral(lo, lo + w / bins as f64) / total * n as f64);
                }
            }
            assert!(chi2 < crit, "width {width}: chi2 {chi2} (critical {crit})");
        }
    }

    /// The guide table's scan finds the cell the binary search finds, for every u on a fine
    /// grid and at the CDF's own values (cell edges) and just below them.
    #[test]
    fn the_guide_table_finds_the_cells_of_the_binary_search() {
        for width in [1.5f32, 0.5, 3.0] {
            let PixelFilter::BlackmanHarris { cdf, start, .. } = PixelFilter::blackman_harris(width) else {
                unreachable!()
            };
            let grid = (0..1 << 16).map(|k| k as f32 / 65_536.0);
            let edges = cdf.iter().flat_map(|&c| [c, f32::from_bits(c.to_bits().saturating_sub(1))]);
            for u in grid.chain(edges).filter(|u| (0.0..1.0).contains(u)) {
                assert_eq!(guided_cell(&cdf, &start, u), cell_of(&cdf, u), "width {width}, u = {u}");
            }
        }
    }

    #[test]
    fn the_box_covers_its_pixel_and_the_window_is_symmetric() {
        assert_eq!(PixelFilter::Box.offset(0.0), -0.5);
        assert_eq!(PixelFilter::Box.offset(0.75), 0.25);
        let f = PixelFilter::blackman_harris(1.5);
        assert!(f.offset(0.5).abs() < 1e-4);
        for u in [0.01f32, 0.1, 0.3, 0.45] {
            assert!((f.offset(u) + f.offset(1.0 - u)).abs() < 1e-3, "{u}");
        }
        assert!(PixelFilter::from_name("nope", 1.5).is_none());
    }
}
