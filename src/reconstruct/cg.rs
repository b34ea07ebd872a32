//! Preconditioned conjugate gradients (Shewchuk 1994) on the weighted screened Poisson
//! normal equations, the three colour channels at once (they share their row weights):
//!
//!   (α² W_g + D_xᵀ W_x D_x + D_yᵀ W_y D_y) I_c = α² W_g I^g_c + D_xᵀ W_x I^dx_c + D_yᵀ W_y I^dy_c
//!
//! matrix-free, with a Jacobi preconditioner, in f32 (dot products summed in f64 per row).
//!
//! Layout, for speed: images are "row-planar" (`RowPlanar`: row y holds its R, G and B rows
//! one after the other), so every loop runs over contiguous rows of one channel and
//! vectorises, and each weight row is read once for the three channels. One CG step is
//! three passes over the image: A·d with d·A·d; the updates of x and r with r·M⁻¹r; the new
//! direction. Every pass runs over bands of `BAND` rows in parallel and sums its dot
//! products band by band in order, so the result does not depend on the thread count.

use rayon::prelude::*;

/// Rows per parallel band.
pub const BAND: usize = 16;

/// Three channels of a W×H image stored row by row: row y is R, G, B of that row (3·W floats).
#[derive(Clone, Debug, PartialEq)]
pub struct RowPlanar {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

impl RowPlanar {
    pub fn zeros(width: usize, height: usize) -> RowPlanar {
        RowPlanar { width, height, data: vec![0.0; 3 * width * height] }
    }

    /// From three row-major planes (a non-finite value becomes 0).
    pub fn from_planes(planes: [&[f64]; 3], width: usize, height: usize) -> RowPlanar {
        let mut out = RowPlanar::zeros(width, height);
        out.data.par_chunks_mut(3 * width).enumerate().for_each(|(y, row)| {
            for (c, plane) in planes.iter().enumerate() {
                let src = &plane[y * width..(y + 1) * width];
                for (o, &v) in row[c * width..(c + 1) * width].iter_mut().zip(src) {
                    *o = if v.is_finite() { v as f32 } else { 0.0 };
                }
            }
        });
        out
    }

    /// From an interleaved RGB image (W·H·3), times `scale` (a non-finite value becomes 0).
    pub fn from_interleaved(data: &[f32], width: usize, height: usize, scale: f32) -> RowPlanar {
        let mut out = RowPlanar::zeros(width, height);
        out.data.par_chunks_mut(3 * width).zip(data.par_chunks(3 * width)).for_each(|(row, src)| {
            for (x, px) in src.chunks_exact(3).enumerate() {
                for c in 0..3 {
                    let v = px[c] * scale;
                    row[c * width + x] = if v.is_finite() { v } else { 0.0 };
                }
            }
        });
        out
    }

    /// A copy times `scale`.
    pub fn scaled(&self, scale: f32) -> RowPlanar {
        RowPlanar { width: self.width, height: self.height, data: self.data.par_iter().map(|v| v * scale).collect() }
    }

    /// Multiplies every value by `scale`, in place.
    pub fn scale(&mut self, scale: f32) {
        self.data.par_iter_mut().for_each(|v| *v *= scale);
    }

    /// As an interleaved RGB image, plus `add` (interleaved, if any), clipped at `floor`.
    pub fn to_interleaved(&self, add: Option<&[f32]>, floor: f32) -> Vec<f32> {
        let w = self.width;
        let mut out = vec![0.0f32; 3 * w * self.height];
        out.par_chunks_mut(3 * w).zip(self.data.par_chunks(3 * w)).enumerate().for_each(|(y, (dst, row))| {
            for (x, px) in dst.chunks_exact_mut(3).enumerate() {
                for c in 0..3 {
                    let a = add.map_or(0.0, |a| a[3 * (y * w + x) + c]);
                    px[c] = (row[c * w + x] + a).max(floor);
                }
            }
        });
        out
    }

    /// Channel c as a row-major f32 plane.
    pub fn channel(&self, c: usize) -> Vec<f32> {
        let w = self.width;
        self.data.par_chunks(3 * w).flat_map_iter(|row| row[c * w..(c + 1) * w].iter().copied()).collect()
    }

    /// Sets channel c from a row-major plane.
    pub fn set_channel(&mut self, c: usize, src: &[f32]) {
        let w = self.width;
        self.data
            .par_chunks_mut(3 * w)
            .zip(src.par_chunks(w))
            .for_each(|(row, s)| row[c * w..(c + 1) * w].copy_from_slice(s));
    }

    /// Channel c as a row-major plane, in f64 (for tests).
    pub fn plane(&self, c: usize) -> Vec<f64> {
        let w = self.width;
        self.data.chunks_exact(3 * w).flat_map(|row| row[c * w..(c + 1) * w].iter().map(|&v| v as f64)).collect()
    }

    #[inline]
    pub fn row(&self, y: usize, c: usize) -> &[f32] {
        let s = (3 * y + c) * self.width;
        &self.data[s..s + self.width]
    }

    #[inline]
    pub fn row_mut(&mut self, y: usize, c: usize) -> &mut [f32] {
        let s = (3 * y + c) * self.width;
        &mut self.data[s..s + self.width]
    }
}

/// Σ a·b over a row, in eight independent lanes (so that it vectorises), returned in f64.
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f64 {
    let mut lanes = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            lanes[k] += x[k] * y[k];
        }
    }
    lanes.iter().map(|&v| v as f64).sum::<f64>() + tail as f64
}

/// Σ a²·m over a row (the preconditioned norm), as `dot`.
#[inline]
fn dot_weighted(a: &[f32], m: &[f32]) -> f64 {
    let mut lanes = [0.0f32; 8];
    let (ca, cm) = (a.chunks_exact(8), m.chunks_exact(8));
    let tail: f32 = ca.remainder().iter().zip(cm.remainder()).map(|(x, y)| x * x * y).sum();
    for (x, y) in ca.zip(cm) {
        for k in 0..8 {
            lanes[k] += x[k] * x[k] * y[k];
        }
    }
    lanes.iter().map(|&v| v as f64).sum::<f64>() + tail as f64
}

/// Per-pixel row weights, row-major: of the pixel's primal row (`g`) and of its forward
/// differences (`x`, `y`), the latter zero where the difference does not exist (last column
/// for x, last row for y).
pub struct Weights {
    pub g: Vec<f32>,
    pub x: Vec<f32>,
    pub y: Vec<f32>,
}

impl Weights {
    /// All existing rows weighted 1: plain (L2) screened Poisson.
    pub fn ones(width: usize, height: usize) -> Weights {
        let n = width * height;
        Weights {
            g: vec![1.0; n],
            x: (0..n).map(|i| f32::from(i % width + 1 < width)).collect(),
            y: (0..n).map(|i| f32::from(i / width + 1 < height)).collect(),
        }
    }

    /// 1 / diagonal of the operator (the Jacobi preconditioner) for row y, into `out`.
    fn inverse_diagonal_row(&self, width: usize, a2: f32, y: usize, out: &mut [f32]) {
        let at = y * width;
        let (g, wx, wy) = (&self.g[at..at + width], &self.x[at..at + width], &self.y[at..at + width]);
        for x in 0..width {
            let mut d = a2 * g[x] + wx[x] + wy[x];
            if x > 0 {
                d += wx[x - 1];
            }
            if y > 0 {
                d += self.y[at - width + x];
            }
            out[x] = 1.0 / d.max(1e-30);
        }
    }
}

/// The vectors of a CG solve: M⁻¹ (per pixel, shared by the channels), r, d and A·d.
pub struct Workspace {
    dinv: Vec<f32>,
    r: RowPlanar,
    d: RowPlanar,
    ad: RowPlanar,
}

impl Workspace {
    pub fn new(width: usize, height: usize) -> Workspace {
        let z = || RowPlanar::zeros(width, height);
        Workspace { dinv: vec![0.0; width * height], r: z(), d: z(), ad: z() }
    }
}

/// The data of the problem: primal and gradients.
pub struct Problem {
    pub alpha: f32,
    pub primal: RowPlanar,
    pub dx: RowPlanar,
    pub dy: RowPlanar,
}

/// Runs `f(first_row, band)` over the bands of `out` in parallel; the results in band order.
fn bands<R: Send>(out: &mut RowPlanar, f: impl Fn(usize, &mut [f32]) -> R + Sync) -> Vec<R> {
    let w = out.width;
    out.data.par_chunks_mut(3 * BAND * w).enumerate().map(|(b, chunk)| f(b * BAND, chunk)).collect()
}

fn sum3(parts: impl IntoIterator<Item = [f64; 3]>) -> [f64; 3] {
    parts.into_iter().fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]])
}

impl Problem {
    pub fn width(&self) -> usize {
        self.primal.width
    }
    pub fn height(&self) -> usize {
        self.primal.height
    }

    /// out = A·v for the rows of `out` (a band starting at row `y0`); returns Σ v·(A·v).
    fn apply_band(&self, wts: &Weights, v: &RowPlanar, y0: usize, out: &mut [f32]) -> [f64; 3] {
        let (w, h) = (self.width(), self.height());
        let a2 = self.alpha * self.alpha;
        let mut sums = [0.0f64; 3];
        for (r, rows) in out.chunks_exact_mut(3 * w).enumerate() {
            let y = y0 + r;
            let at = y * w;
            let (g, wx, wd) = (&wts.g[at..at + w], &wts.x[at..at + w], &wts.y[at..at + w]);
            for (c, o) in rows.chunks_exact_mut(w).enumerate() {
                let vr = v.row(y, c);
                for ((o, &gi), &vi) in o.iter_mut().zip(g).zip(vr) {
                    *o = a2 * gi * vi;
                }
                // D_xᵀ W_x D_x: the flux to the right neighbour, and the one from the left
                for ((o, &k), (&vi, &vn)) in o[..w - 1].iter_mut().zip(wx).zip(vr.iter().zip(&vr[1..])) {
                    *o += k * (vi - vn);
                }
                for ((o, &k), (&vi, &vn)) in o[1..].iter_mut().zip(wx).zip(vr[1..].iter().zip(vr)) {
                    *o += k * (vi - vn);
                }
                if y + 1 < h {
                    for ((o, &k), (&vi, &vn)) in o.iter_mut().zip(wd).zip(vr.iter().zip(v.row(y + 1, c))) {
                        *o += k * (vi - vn);
                    }
                }
                if y > 0 {
                    let wu = &wts.y[at - w..at];
                    for ((o, &k), (&vi, &vn)) in o.iter_mut().zip(wu).zip(vr.iter().zip(v.row(y - 1, c))) {
                        *o += k * (vi - vn);
                    }
                }
                sums[c] += dot(vr, o);
            }
        }
        sums
    }

    /// The right-hand side α² W_g I^g + D_xᵀ W_x I^dx + D_yᵀ W_y I^dy for the band's rows.
    fn rhs_band(&self, wts: &Weights, y0: usize, out: &mut [f32]) {
        let w = self.width();
        let a2 = self.alpha * self.alpha;
        for (r, rows) in out.chunks_exact_mut(3 * w).enumerate() {
            let y = y0 + r;
            let at = y * w;
            let (g, wx, wd) = (&wts.g[at..at + w], &wts.x[at..at + w], &wts.y[at..at + w]);
            for (c, o) in rows.chunks_exact_mut(w).enumerate() {
                let (p, gx, gy) = (self.primal.row(y, c), self.dx.row(y, c), self.dy.row(y, c));
                for i in 0..w {
                    o[i] = a2 * g[i] * p[i] - wx[i] * gx[i] - wd[i] * gy[i];
                }
                for ((o, &k), &v) in o[1..].iter_mut().zip(wx).zip(gx) {
                    *o += k * v;
                }
                if y > 0 {
                    let (wu, gu) = (&wts.y[at - w..at], self.dy.row(y - 1, c));
                    for ((o, &k), &v) in o.iter_mut().zip(wu).zip(gu) {
                        *o += k * v;
                    }
                }
            }
        }
    }

    /// Preconditioned CG from `x` (updated in place): at most `iters` steps; a channel stops
    /// moving once ‖r‖ ≤ tol·‖b‖; returns early with the current iterate once `stop()` is true
    /// (asked every step).
    pub fn solve(&self, wts: &Weights, x: &mut RowPlanar, iters: usize, tol: f64, stop: &(dyn Fn() -> bool + Sync)) {
        let mut ws = Workspace::new(self.width(), self.height());
        self.solve_in(&mut ws, wts, x, iters, tol, stop);
    }

    /// `solve` with its vectors in `ws` (every entry is written before it is read), so that
    /// repeated solves (IRLS) do not fault in fresh pages each time.
    pub fn solve_in(
        &self,
        ws: &mut Workspace,
        wts: &Weights,
        x: &mut RowPlanar,
        iters: usize,
        tol: f64,
        stop: &(dyn Fn() -> bool + Sync),
    ) {
        let Workspace { dinv, r, d, ad } = ws;
        let w = self.width();
        let a2 = self.alpha * self.alpha;
        // One pass, band by band (each band's rows stay in cache): M⁻¹, r = b − A·x, d = M⁻¹r,
        // and ‖b‖², r·M⁻¹r.
        let norms: Vec<[[f64; 3]; 2]> = dinv
            .par_chunks_mut(BAND * w)
            .zip(r.data.par_chunks_mut(3 * BAND * w))
            .zip(d.data.par_chunks_mut(3 * BAND * w))
            .enumerate()
            .map(|(b, ((mb, rb), db))| {
                let y0 = b * BAND;
                self.rhs_band(wts, y0, rb);
                self.apply_band(wts, x, y0, db); // A·x, for now
                let mut s = [[0.0; 3]; 2];
                for (k, ((m, rows), drows)) in
                    mb.chunks_exact_mut(w).zip(rb.chunks_exact_mut(3 * w)).zip(db.chunks_exact_mut(3 * w)).enumerate()
                {
                    wts.inverse_diagonal_row(w, a2, y0 + k, m);
                    for (c, (rr, dr)) in rows.chunks_exact_mut(w).zip(drows.chunks_exact_mut(w)).enumerate() {
                        s[0][c] += dot(rr, rr);
                        for ((ri, di), &mi) in rr.iter_mut().zip(dr.iter_mut()).zip(m.iter()) {
                            *ri -= *di;
                            *di = *ri * mi;
                        }
                        s[1][c] += dot_weighted(rr, m);
                    }
                }
                s
            })
            .collect();
        let bnorm2 = sum3(norms.iter().map(|s| s[0]));
        let mut rz = sum3(norms.iter().map(|s| s[1]));
        let tol2 = tol * tol;
        let mut rr = [f64::INFINITY; 3];
        for _ in 0..iters {
            let moving: [bool; 3] = std::array::from_fn(|c| rr[c] > tol2 * bnorm2[c] && rz[c] > 0.0);
            if stop() || !moving.iter().any(|&m| m) {
                break;
            }
            let dad = sum3(bands(ad, |y0, out| self.apply_band(wts, d, y0, out)));
            let step: [f32; 3] =
                std::array::from_fn(|c| if moving[c] && dad[c] > 0.0 { (rz[c] / dad[c]) as f32 } else { 0.0 });
            // x += a·d, r −= a·A·d; Σ r·M⁻¹r and Σ r·r
            let sums: Vec<[[f64; 3]; 2]> = x
                .data
                .par_chunks_mut(3 * BAND * w)
                .zip(r.data.par_chunks_mut(3 * BAND * w))
                .enumerate()
                .map(|(b, (xb, rb))| {
                    let mut s = [[0.0f64; 3]; 2];
                    for (k, (xrows, rrows)) in xb.chunks_exact_mut(3 * w).zip(rb.chunks_exact_mut(3 * w)).enumerate() {
                        let y = b * BAND + k;
                        let m = &dinv[y * w..(y + 1) * w];
                        for (c, (xr, rr)) in xrows.chunks_exact_mut(w).zip(rrows.chunks_exact_mut(w)).enumerate() {
                            let a = step[c];
                            for ((xi, ri), (&di, &adi)) in
                                xr.iter_mut().zip(rr.iter_mut()).zip(d.row(y, c).iter().zip(ad.row(y, c)))
                            {
                                *xi += a * di;
                                *ri -= a * adi;
                            }
                            s[0][c] += dot_weighted(rr, m);
                            s[1][c] += dot(rr, rr);
                        }
                    }
                    s
                })
                .collect();
            let rz_new = sum3(sums.iter().map(|s| s[0]));
            rr = sum3(sums.iter().map(|s| s[1]));
            let beta: [f32; 3] = std::array::from_fn(|c| if rz[c] > 0.0 { (rz_new[c] / rz[c]) as f32 } else { 0.0 });
            rz = rz_new;
            self.direction(d, r, dinv, beta);
        }
    }

    /// (A·x, b) of the weighted problem: the normal equations' two sides, for tests.
    #[cfg(test)]
    pub fn operator_and_rhs(&self, wts: &Weights, x: &RowPlanar) -> (RowPlanar, RowPlanar) {
        let (mut ax, mut b) =
            (RowPlanar::zeros(self.width(), self.height()), RowPlanar::zeros(self.width(), self.height()));
        bands(&mut ax, |y0, out| self.apply_band(wts, x, y0, out));
        bands(&mut b, |y0, out| self.rhs_band(wts, y0, out));
        (ax, b)
    }

    /// d = M⁻¹ r + β·d.
    fn direction(&self, d: &mut RowPlanar, r: &RowPlanar, dinv: &[f32], beta: [f32; 3]) {
        let w = self.width();
        bands(d, |y0, band| {
            for (k, rows) in band.chunks_exact_mut(3 * w).enumerate() {
                let y = y0 + k;
                let m = &dinv[y * w..(y + 1) * w];
                for (c, dr) in rows.chunks_exact_mut(w).enumerate() {
                    for ((di, &ri), &mi) in dr.iter_mut().zip(r.row(y, c)).zip(m) {
                        *di = ri * mi + beta[c] * *di;
                    }
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    /// With arbitrary positive row weights (as IRLS gives), CG reaches the minimiser of the
    /// weighted problem: the one a plain f64 Gauss–Seidel iteration on the same energy,
    /// written from the energy itself, converges to.
    #[test]
    fn weighted_cg_reaches_the_weighted_minimiser() {
        let (w, h) = (21, BAND + 3);
        let n = w * h;
        let mut s = IndependentSampler::new(7, 2);
        let mut rnd = |lo: f64, hi: f64| lo + (hi - lo) * s.next_1d() as f64;
        let planes: Vec<[Vec<f64>; 3]> =
            (0..3).map(|_| std::array::from_fn(|_| (0..n).map(|_| rnd(-1.0, 1.0)).collect())).collect();
        let mut wts = Weights::ones(w, h);
        for v in [&mut wts.g, &mut wts.x, &mut wts.y] {
            v.iter_mut().for_each(|x| *x *= rnd(0.01, 10.0) as f32);
        }
        let alpha = 0.3f64;
        let rp = |k: usize| RowPlanar::from_planes([&planes[0][k], &planes[1][k], &planes[2][k]], w, h);
        let p = Problem { alpha: alpha as f32, primal: rp(0), dx: rp(1), dy: rp(2) };
        let mut x = RowPlanar::zeros(w, h);
        p.solve(&wts, &mut x, 2000, 1e-7, &|| false);
        for (c, [pg, gx, gy]) in planes.iter().enumerate() {
            // E(I) = Σ α² g_i (I_i − p_i)² + Σ x_i (I_{i+1} − I_i − dx_i)² + Σ y_i (I_{i+w} − I_i − dy_i)²:
            // each Gauss–Seidel step sets I_i to the minimiser of E over I_i alone
            let mut v = vec![0.0f64; n];
            for _ in 0..20_000 {
                for i in 0..n {
                    let (xi, yi) = (i % w, i / w);
                    let g = alpha * alpha * wts.g[i] as f64;
                    let (mut num, mut den) = (g * pg[i], g);
                    if xi + 1 < w {
                        let k = wts.x[i] as f64;
                        num += k * (v[i + 1] - gx[i]);
                        den += k;
                    }
                    if xi > 0 {
                        let k = wts.x[i - 1] as f64;
                        num += k * (v[i - 1] + gx[i - 1]);
                        den += k;
                    }
                    if yi + 1 < h {
                        let k = wts.y[i] as f64;
                        num += k * (v[i + w] - gy[i]);
                        den += k;
                    }
                    if yi > 0 {
                        let k = wts.y[i - w] as f64;
                        num += k * (v[i - w] + gy[i - w]);
                        den += k;
                    }
                    v[i] = num / den;
                }
            }
            let got = x.plane(c);
            let scale = v.iter().fold(0.0f64, |m, a| m.max(a.abs()));
            for i in 0..n {
                assert!((got[i] - v[i]).abs() < 2e-4 * scale, "channel {c} pixel {i}: cg {} vs gs {}", got[i], v[i]);
            }
        }
    }
}
