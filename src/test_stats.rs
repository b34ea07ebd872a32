//! Statistics shared by the sampling tests: Pearson's chi-square of observed counts against
//! a pmf, over the bins expected to hold at least 5 (the rest pooled into one), and its
//! 1e-3 critical value by the Wilson–Hilferty approximation.

/// (chi-square, degrees of freedom) of `counts` (n draws in all) against `pmf`.
pub fn chi_square(counts: &[usize], pmf: &[f64], n: usize) -> (f64, usize) {
    let (mut chi2, mut bins) = (0.0, 0usize);
    let (mut pooled_e, mut pooled_c) = (0.0, 0.0);
    for (&c, &q) in counts.iter().zip(pmf) {
        let e = q * n as f64;
        if e >= 5.0 {
            chi2 += (c as f64 - e).powi(2) / e;
            bins += 1;
        } else {
            pooled_e += e;
            pooled_c += c as f64;
        }
    }
    if pooled_e >= 5.0 {
        chi2 += (pooled_c - pooled_e).powi(2) / pooled_e;
        bins += 1;
    }
    (chi2, bins.saturating_sub(1).max(1))
}

/// The chi-square value exceeded with probability 1e-3 at `df` degrees of freedom.
pub fn critical_1e3(df: usize) -> f64 {
    let df = df as f64;
    df * (1.0 - 2.0 / (9.0 * df) + 3.09 * (2.0 / (9.0 * df)).sqrt()).powi(3)
}
