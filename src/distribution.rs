//! Piecewise-constant 1-D distribution: sample an index with probability ∝ weight.

#[derive(Clone, Debug, Default)]
pub struct Distribution1D {
    cdf: Vec<f32>,
    pmf: Vec<f32>,
    total: f64,
}

impl Distribution1D {
    /// Weights must be finite and ≥ 0; non-finite or negative weights count as 0.
    pub fn new(weights: &[f32]) -> Self {
        let mut total = 0.0f64;
        let w: Vec<f64> = weights.iter().map(|&x| if x.is_finite() && x > 0.0 { x as f64 } else { 0.0 }).collect();
        for x in &w {
            total += x;
        }
        let mut cdf = Vec::with_capacity(w.len());
        let mut pmf = Vec::with_capacity(w.len());
        let mut acc = 0.0f64;
        for x in &w {
            acc += x;
            cdf.push(if total > 0.0 { (acc / total) as f32 } else { 0.0 });
            pmf.push(if total > 0.0 { (x / total) as f32 } else { 0.0 });
        }
        if let Some(last) = cdf.last_mut() {
            if total > 0.0 {
                *last = 1.0;
            }
        }
        Distribution1D { cdf, pmf, total }
    }

    pub fn is_empty(&self) -> bool {
        self.total <= 0.0
    }
    pub fn len(&self) -> usize {
        self.pmf.len()
    }
    pub fn total(&self) -> f64 {
        self.total
    }

    /// Returns (index, probability of that index).
    #[inline]
    pub fn sample(&self, u: f32) -> Option<(usize, f32)> {
        if self.is_empty() {
            return None;
        }
        let i = self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1);
        // skip zero-probability entries that partition_point may land on at the end
        let mut j = i;
        while self.pmf[j] == 0.0 && j > 0 {
            j -= 1;
        }
        Some((j, self.pmf[j]))
    }

    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf.get(i).copied().unwrap_or(0.0)
    }

    /// Like `sample`, also returning u rescaled to [0, 1) within the chosen bin, for reuse.
    #[inline]
    pub fn sample_reuse(&self, u: f32) -> Option<(usize, f32, f32)> {
        let (i, p) = self.sample(u)?;
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        Some((i, p, ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON)))
    }

    /// Samples the piecewise-constant density on [0, 1) with one bin per weight (pbrt's
    /// Distribution1D::SampleContinuous): (x, density at x, bin).
    #[inline]
    pub fn sample_continuous(&self, u: f32) -> Option<(f32, f32, usize)> {
        let (i, p) = self.sample(u)?;
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let t = ((u - lo) / p).clamp(0.0, 0.999_999);
        let n = self.pmf.len() as f32;
        Some(((i as f32 + t) / n, p * n, i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frequencies_match_pmf() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0, 4.0, f32::NAN]);
        let mut counts = [0usize; 5];
        let n = 100_000;
        for k in 0..n {
            let u = (k as f32 + 0.5) / n as f32;
            let (i, p) = d.sample(u).unwrap();
            assert!((p - d.pmf(i)).abs() < 1e-7);
            counts[i] += 1;
        }
        assert_eq!(counts[1], 0);
        assert_eq!(counts[4], 0);
        for (i, &c) in counts.iter().enumerate() {
            assert!((c as f32 / n as f32 - d.pmf(i)).abs() < 1e-3);
        }
    }

    /// Continuous samples fall in the chosen bin, uniformly, with density pmf·n.
    #[test]
    fn continuous_samples_follow_the_density() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        let mut hist = [0usize; 6];
        let n = 60_000;
        for k in 0..n {
            let (x, pdf, i) = d.sample_continuous((k as f32 + 0.5) / n as f32).unwrap();
            assert!((0.0..1.0).contains(&x) && (x * 3.0) as usize == i);
            assert!((pdf - d.pmf(i) * 3.0).abs() < 1e-6);
            hist[(x * 6.0) as usize] += 1;
        }
        let expect = [0.125, 0.125, 0.0, 0.0, 0.375, 0.375];
        for (h, e) in hist.iter().zip(expect) {
            assert!((*h as f32 / n as f32 - e).abs() < 2e-3, "{hist:?}");
        }
    }

    #[test]
    fn empty_distribution_samples_nothing() {
        assert!(Distribution1D::new(&[]).sample(0.3).is_none());
        assert!(Distribution1D::new(&[0.0, 0.0]).sample(0.3).is_none());
    }
}
