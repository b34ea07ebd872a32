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
//! one pass over the image: it finishes the last step (x += a·d, r −= a·A·d) and forms the
//! new direction d = M⁻¹r + βd, A·d and the step's dot products, with β from an expansion
//! of the next r·M⁻¹r (Chronopoulos & Gear 1989; `Problem::iterate`). IRLS's reweighting and
//! the CG's set-up are one pass too (`solve_reweighted_in`): the residuals at x give both
//! the new row weights and r = b − A·x. Every pass runs over bands of `BAND` rows in
//! parallel and sums its dot products band by band in order, so the result does not depend
//! on the thread count. (Measured at 1920×1080 on 2 cores, docs/benchmarks.md: two passes
//! per step and a fused set-up were 12–14% faster than three and a separate weights pass;
//! one pass per step moves 20% fewer bytes — 28 floats a pixel instead of 35 — and was
//! 3–7% faster on 2 threads, equal on 1; recomputing A·d instead of storing it saved bytes
//! but cost more arithmetic, 5%.)

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
    dot3(a, a, m)
}

/// Σ a·b·m over a row, as `dot`.
#[inline]
fn dot3(a: &[f32], b: &[f32], m: &[f32]) -> f64 {
    let mut lanes = [0.0f32; 8];
    let (ca, cb, cm) = (a.chunks_exact(8), b.chunks_exact(8), m.chunks_exact(8));
    let tail: f32 = ca.remainder().iter().zip(cb.remainder()).zip(cm.remainder()).map(|((x, y), z)| x * y * z).sum();
    for ((x, y), z) in ca.zip(cb).zip(cm) {
        for k in 0..8 {
            lanes[k] += x[k] * y[k] * z[k];
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

    /// All rows weighted 0, for a reweighting to overwrite (untouched zero pages until then).
    pub fn zeros(width: usize, height: usize) -> Weights {
        let n = width * height;
        Weights { g: vec![0.0; n], x: vec![0.0; n], y: vec![0.0; n] }
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

    /// The residual r = b − A·x of the last set-up (for tests; the steps leave it behind x).
    #[cfg(test)]
    pub fn residual(&self) -> &RowPlanar {
        &self.r
    }
}

/// (A·v) of one channel's row y into `out`, from v's rows y − 1 (`up`), y and y + 1
/// (`down`; `None` beyond the image). One loop over the row's inner pixels, so that every
/// input is loaded once; a missing row above or below stands in as v's own row (its flux
/// v − v is 0).
#[inline]
#[allow(clippy::too_many_arguments)]
fn stencil_row(
    wts: &Weights,
    a2: f32,
    w: usize,
    y: usize,
    up: Option<&[f32]>,
    v: &[f32],
    down: Option<&[f32]>,
    out: &mut [f32],
) {
    let at = y * w;
    let (g, wx, wd) = (&wts.g[at..at + w], &wts.x[at..at + w], &wts.y[at..at + w]);
    let dn = down.unwrap_or(v);
    let (wu, un) = match up {
        Some(u) => (&wts.y[at - w..at], u),
        None => (wd, v),
    };
    let (dn, wu, un, out, v) = (&dn[..w], &wu[..w], &un[..w], &mut out[..w], &v[..w]);
    let centre = |i: usize| a2 * g[i] * v[i] + wd[i] * (v[i] - dn[i]) + wu[i] * (v[i] - un[i]);
    if w == 1 {
        out[0] = centre(0);
        return;
    }
    out[0] = centre(0) + wx[0] * (v[0] - v[1]);
    out[w - 1] = centre(w - 1) + wx[w - 2] * (v[w - 1] - v[w - 2]);
    // the inner pixels: the fluxes to the right (wx[i]) and from the left (wx[i − 1])
    let m = w - 2;
    let (o, vl, vc, vr) = (&mut out[1..1 + m], &v[..m], &v[1..1 + m], &v[2..2 + m]);
    let (kl, kr, gc, wdc, dnc, wuc, unc) =
        (&wx[..m], &wx[1..1 + m], &g[1..1 + m], &wd[1..1 + m], &dn[1..1 + m], &wu[1..1 + m], &un[1..1 + m]);
    for i in 0..m {
        let c = vc[i];
        o[i] =
            a2 * gc[i] * c + kr[i] * (c - vr[i]) + kl[i] * (c - vl[i]) + wdc[i] * (c - dnc[i]) + wuc[i] * (c - unc[i]);
    }
}

/// One CG step's work on a row of the three channels: finish the last step, x += a·d (when
/// x is given) and r −= a·A·d, then form the new direction d = M⁻¹r + β·d; before the first
/// step (`prev` None) only d = M⁻¹r.
#[inline]
fn advance_row(
    w: usize,
    prev: Option<([f32; 3], [f32; 3])>,
    m: &[f32],
    x: Option<&mut [f32]>,
    r: &mut [f32],
    d: &mut [f32],
    q: &[f32],
) {
    let Some((a, beta)) = prev else {
        for (dc, rc) in d.chunks_exact_mut(w).zip(r.chunks_exact(w)) {
            for ((di, &ri), &mi) in dc.iter_mut().zip(rc).zip(m) {
                *di = ri * mi;
            }
        }
        return;
    };
    if let Some(x) = x {
        for ((xc, dc), &ac) in x.chunks_exact_mut(w).zip(d.chunks_exact(w)).zip(&a) {
            for (xi, &di) in xc.iter_mut().zip(dc) {
                *xi += ac * di;
            }
        }
    }
    for (c, ((rc, dc), qc)) in r.chunks_exact_mut(w).zip(d.chunks_exact_mut(w)).zip(q.chunks_exact(w)).enumerate() {
        let (ac, bc) = (a[c], beta[c]);
        for ((ri, di), (&qi, &mi)) in rc.iter_mut().zip(dc.iter_mut()).zip(qc.iter().zip(m)) {
            *ri -= ac * qi;
            *di = *ri * mi + bc * *di;
        }
    }
}

/// A CG step's sums per channel (each band's, then added in band order): d·A·d, r·M⁻¹r, r·r,
/// r·M⁻¹A·d and (A·d)·M⁻¹(A·d).
#[derive(Default)]
struct StepSums {
    dad: [f64; 3],
    rz: [f64; 3],
    rr: [f64; 3],
    rzq: [f64; 3],
    qzq: [f64; 3],
}

impl StepSums {
    fn add(self, o: StepSums) -> StepSums {
        let f = |a: [f64; 3], b: [f64; 3]| std::array::from_fn(|c| a[c] + b[c]);
        StepSums {
            dad: f(self.dad, o.dad),
            rz: f(self.rz, o.rz),
            rr: f(self.rr, o.rr),
            rzq: f(self.rzq, o.rzq),
            qzq: f(self.qzq, o.qzq),
        }
    }
}

/// The data of the problem: primal and gradients.
pub struct Problem {
    pub alpha: f32,
    pub primal: RowPlanar,
    pub dx: RowPlanar,
    pub dy: RowPlanar,
}

#[cfg(test)]
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
            for (c, o) in rows.chunks_exact_mut(w).enumerate() {
                let up = (y > 0).then(|| v.row(y - 1, c));
                let down = (y + 1 < h).then(|| v.row(y + 1, c));
                stencil_row(wts, a2, w, y, up, v.row(y, c), down, o);
                sums[c] += dot(v.row(y, c), o);
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
    /// repeated solves do not fault in fresh pages each time.
    pub fn solve_in(
        &self,
        ws: &mut Workspace,
        wts: &Weights,
        x: &mut RowPlanar,
        iters: usize,
        tol: f64,
        stop: &(dyn Fn() -> bool + Sync),
    ) {
        let Workspace { dinv, r, d, .. } = ws;
        let w = self.width();
        let a2 = self.alpha * self.alpha;
        // One pass, band by band (each band's rows stay in cache): M⁻¹, r = b − A·x, and
        // ‖b‖², r·M⁻¹r (d holds A·x meanwhile).
        let norms: Vec<[[f64; 3]; 2]> = dinv
            .par_chunks_mut(BAND * w)
            .zip(r.data.par_chunks_mut(3 * BAND * w))
            .zip(d.data.par_chunks_mut(3 * BAND * w))
            .enumerate()
            .map(|(b, ((mb, rb), db))| {
                let y0 = b * BAND;
                self.rhs_band(wts, y0, rb);
                self.apply_band(wts, x, y0, db);
                let mut s = [[0.0; 3]; 2];
                for (k, ((m, rows), drows)) in
                    mb.chunks_exact_mut(w).zip(rb.chunks_exact_mut(3 * w)).zip(db.chunks_exact(3 * w)).enumerate()
                {
                    wts.inverse_diagonal_row(w, a2, y0 + k, m);
                    for (c, (rr, dr)) in rows.chunks_exact_mut(w).zip(drows.chunks_exact(w)).enumerate() {
                        s[0][c] += dot(rr, rr);
                        for (ri, di) in rr.iter_mut().zip(dr) {
                            *ri -= *di;
                        }
                        s[1][c] += dot_weighted(rr, m);
                    }
                }
                s
            })
            .collect();
        let bnorm2 = sum3(norms.iter().map(|s| s[0]));
        let rz = sum3(norms.iter().map(|s| s[1]));
        self.iterate(ws, wts, x, bnorm2, rz, iters, tol, stop);
    }

    /// One IRLS step: new row weights `rule(‖e‖_RGB)` from the residuals e of x's rows (e_g
    /// = α(I^g − x), e_x = I^dx − D_x x, e_y = I^dy − D_y x; 0 where a difference does not
    /// exist), into `wts`, then `solve_in` under them from x. The reweighting and the CG's
    /// set-up are one pass: the same residuals give r = b − A·x = α²W_g(I^g − x) + D_xᵀW_x e_x
    /// + D_yᵀW_y e_y.
    ///
    /// ‖b‖² (the stopping rule's scale) costs a second product per row, so it is summed only
    /// for a positive `tol`; with `tol` 0 a channel stops where its residual is exactly zero.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_reweighted_in(
        &self,
        ws: &mut Workspace,
        wts: &mut Weights,
        x: &mut RowPlanar,
        rule: impl Fn(f32) -> f32 + Sync,
        iters: usize,
        tol: f64,
        stop: &(dyn Fn() -> bool + Sync),
    ) {
        let (w, h) = (self.width(), self.height());
        let (alpha, a2) = (self.alpha, self.alpha * self.alpha);
        let sol: &RowPlanar = x;
        let Weights { g, x: wx, y: wy } = wts;
        let Workspace { dinv, r, .. } = ws;
        // the residuals of row y: e_g, e_x and e_y per channel (3·w each), and their norms
        let residuals = |y: usize, eg: &mut [f32], ex: &mut [f32], ey: &mut [f32], n: &mut [Vec<f32>; 3]| {
            for c in 0..3 {
                let (s, pr, gx, gy) = (sol.row(y, c), self.primal.row(y, c), self.dx.row(y, c), self.dy.row(y, c));
                let (egc, exc, eyc) =
                    (&mut eg[c * w..(c + 1) * w], &mut ex[c * w..(c + 1) * w], &mut ey[c * w..(c + 1) * w]);
                for (e, (&si, &pi)) in egc.iter_mut().zip(s.iter().zip(pr)) {
                    *e = pi - si;
                }
                for (e, (&gi, (&si, &sn))) in exc.iter_mut().zip(gx.iter().zip(s.iter().zip(&s[1..]))) {
                    *e = gi - (sn - si);
                }
                exc[w - 1] = 0.0;
                if y + 1 < h {
                    for (e, (&gi, (&si, &sn))) in eyc.iter_mut().zip(gy.iter().zip(s.iter().zip(sol.row(y + 1, c)))) {
                        *e = gi - (sn - si);
                    }
                } else {
                    eyc.fill(0.0);
                }
                let [ng, nx, ny] = n;
                if c == 0 {
                    ng.fill(0.0);
                    nx.fill(0.0);
                    ny.fill(0.0);
                }
                for (o, &e) in ng.iter_mut().zip(&*egc) {
                    *o += (alpha * e) * (alpha * e);
                }
                for (o, &e) in nx.iter_mut().zip(&*exc) {
                    *o += e * e;
                }
                for (o, &e) in ny.iter_mut().zip(&*eyc) {
                    *o += e * e;
                }
            }
        };
        let norms: Vec<[[f64; 3]; 2]> = g
            .par_chunks_mut(BAND * w)
            .zip(wx.par_chunks_mut(BAND * w))
            .zip(wy.par_chunks_mut(BAND * w))
            .zip(dinv.par_chunks_mut(BAND * w))
            .zip(r.data.par_chunks_mut(3 * BAND * w))
            .enumerate()
            .map(|(b, ((((gb, xb), yb), mb), rb))| {
                let y0 = b * BAND;
                let (mut eg, mut ex, mut ey) = (vec![0.0f32; 3 * w], vec![0.0f32; 3 * w], vec![0.0f32; 3 * w]);
                let mut n = [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]];
                let mut bb = vec![0.0f32; w];
                // the row above the band: its e_y and W_y (D_yᵀ reaches up one row)
                let (mut ey_up, mut wy_up) = (vec![0.0f32; 3 * w], vec![0.0f32; w]);
                if y0 > 0 {
                    residuals(y0 - 1, &mut eg, &mut ex, &mut ey_up, &mut n);
                    for (o, &v) in wy_up.iter_mut().zip(&n[2]) {
                        *o = rule(v.sqrt());
                    }
                }
                let mut s = [[0.0f64; 3]; 2];
                for (k, ((((gr, xr), yr), m), rows)) in gb
                    .chunks_exact_mut(w)
                    .zip(xb.chunks_exact_mut(w))
                    .zip(yb.chunks_exact_mut(w))
                    .zip(mb.chunks_exact_mut(w))
                    .zip(rb.chunks_exact_mut(3 * w))
                    .enumerate()
                {
                    let y = y0 + k;
                    residuals(y, &mut eg, &mut ex, &mut ey, &mut n);
                    for (o, &v) in gr.iter_mut().zip(&n[0]) {
                        *o = rule(v.sqrt());
                    }
                    for (o, &v) in xr[..w - 1].iter_mut().zip(&n[1]) {
                        *o = rule(v.sqrt());
                    }
                    xr[w - 1] = 0.0;
                    if y + 1 < h {
                        for (o, &v) in yr.iter_mut().zip(&n[2]) {
                            *o = rule(v.sqrt());
                        }
                    } else {
                        yr.fill(0.0);
                    }
                    for (mi, ((&gi, &xi), (&yi, &ui))) in
                        m.iter_mut().zip(gr.iter().zip(&*xr).zip(yr.iter().zip(&wy_up)))
                    {
                        *mi = a2 * gi + xi + yi + ui;
                    }
                    for (mi, &xl) in m[1..].iter_mut().zip(&*xr) {
                        *mi += xl;
                    }
                    for mi in m.iter_mut() {
                        *mi = 1.0 / mi.max(1e-30);
                    }
                    for (c, rr) in rows.chunks_exact_mut(w).enumerate() {
                        let cw = c * w..(c + 1) * w;
                        let (p, gx, gy) = (self.primal.row(y, c), self.dx.row(y, c), self.dy.row(y, c));
                        let gu = if y > 0 { self.dy.row(y - 1, c) } else { gy }; // ×0 at y = 0
                        let (egc, exc, eyc, euc) = (&eg[cw.clone()], &ex[cw.clone()], &ey[cw.clone()], &ey_up[cw]);
                        // r and b: the primal and vertical terms, then the flux from the left
                        for (i, ri) in rr.iter_mut().enumerate() {
                            *ri = a2 * gr[i] * egc[i] - xr[i] * exc[i] + wy_up[i] * euc[i] - yr[i] * eyc[i];
                        }
                        for (ri, (&k, &e)) in rr[1..].iter_mut().zip(xr.iter().zip(exc)) {
                            *ri += k * e;
                        }
                        if tol > 0.0 {
                            // ‖b‖², for the stopping rule alone
                            for (i, bi) in bb.iter_mut().enumerate() {
                                *bi = a2 * gr[i] * p[i] - xr[i] * gx[i] + wy_up[i] * gu[i] - yr[i] * gy[i];
                            }
                            for (bi, (&k, &v)) in bb[1..].iter_mut().zip(xr.iter().zip(gx)) {
                                *bi += k * v;
                            }
                            s[0][c] += dot(&bb, &bb);
                        }
                        s[1][c] += dot_weighted(rr, m);
                    }
                    std::mem::swap(&mut ey, &mut ey_up);
                    wy_up.copy_from_slice(yr);
                }
                s
            })
            .collect();
        let bnorm2 = sum3(norms.iter().map(|s| s[0]));
        let rz = sum3(norms.iter().map(|s| s[1]));
        self.iterate(ws, wts, x, bnorm2, rz, iters, tol, stop);
    }

    /// The CG steps from a set-up workspace (r = b − A·x and M⁻¹ in `ws`; ‖b‖² and r·M⁻¹r
    /// given), one pass over the image per step. Step k's pass finishes step k − 1 — x += a·d,
    /// r −= a·A·d — and in the same sweep forms the new direction d = M⁻¹r + βd, A·d and the
    /// sums d·A·d, r·M⁻¹r, r·r, r·M⁻¹A·d and (A·d)·M⁻¹(A·d). β must be known before the sweep,
    /// so the next r·M⁻¹r is taken from the last three by expanding (r − a·A·d)·M⁻¹(r − a·A·d)
    /// (Chronopoulos & Gear 1989), while the step length a uses r·M⁻¹r summed from r itself.
    /// After the last step a short pass applies x += a·d (r is left as it was: the next
    /// reweighting recomputes it). Each band needs the new d one row beyond its ends, rows its
    /// neighbours own and overwrite meanwhile: it computes them itself from copies of their
    /// old d, r and A·d (every band's first and last rows, taken before the pass), so no band
    /// reads a row another is writing.
    #[allow(clippy::too_many_arguments)]
    fn iterate(
        &self,
        ws: &mut Workspace,
        wts: &Weights,
        x: &mut RowPlanar,
        bnorm2: [f64; 3],
        rz0: [f64; 3],
        iters: usize,
        tol: f64,
        stop: &(dyn Fn() -> bool + Sync),
    ) {
        let Workspace { dinv, r, d, ad: q } = ws;
        let (w, h) = (self.width(), self.height());
        let a2 = self.alpha * self.alpha;
        let tol2 = tol * tol;
        let (nb, row3) = (h.div_ceil(BAND), 3 * w);
        // the last step's length a and the next direction's β, once a step has been formed
        let mut prev: Option<([f32; 3], [f32; 3])> = None;
        let mut moving: [bool; 3] = std::array::from_fn(|c| rz0[c] > 0.0);
        let mut halo = vec![0.0f32; nb * 6 * row3];
        for _ in 0..iters {
            if stop() || !moving.iter().any(|&m| m) {
                break;
            }
            // (0) each band's first and last rows of d, r and A·d, before anyone overwrites them
            let (dd, rr, qq): (&RowPlanar, &RowPlanar, &RowPlanar) = (d, r, q);
            halo.par_chunks_mut(6 * row3).enumerate().for_each(|(b, hb)| {
                let (y0, y1) = (b * BAND, ((b + 1) * BAND).min(h));
                for (j, y) in [y0, y1 - 1].into_iter().enumerate() {
                    let rows = y * row3..(y + 1) * row3;
                    let o = &mut hb[3 * j * row3..3 * (j + 1) * row3];
                    o[..row3].copy_from_slice(&dd.data[rows.clone()]);
                    o[row3..2 * row3].copy_from_slice(&rr.data[rows.clone()]);
                    o[2 * row3..].copy_from_slice(&qq.data[rows]);
                }
            });
            // (1) the sweep, band by band: finish the last step, form d, A·d and the sums
            let (dinv_ref, halo_ref): (&[f32], &[f32]) = (dinv, &halo);
            let parts: Vec<StepSums> = x
                .data
                .par_chunks_mut(BAND * row3)
                .zip(r.data.par_chunks_mut(BAND * row3))
                .zip(d.data.par_chunks_mut(BAND * row3))
                .zip(q.data.par_chunks_mut(BAND * row3))
                .enumerate()
                .map(|(b, (((xb, rb), db), qb))| {
                    let (y0, y1) = (b * BAND, ((b + 1) * BAND).min(h));
                    let m = |y: usize| &dinv_ref[y * w..(y + 1) * w];
                    // the new d of a neighbour band's first (j = 0) or last (j = 1) row
                    let halo_row = |nbr: usize, j: usize, y: usize| -> Vec<f32> {
                        let c = &halo_ref[(6 * nbr + 3 * j) * row3..(6 * nbr + 3 * j + 3) * row3];
                        let (mut dn, mut rn) = (c[..row3].to_vec(), c[row3..2 * row3].to_vec());
                        advance_row(w, prev, m(y), None, &mut rn, &mut dn, &c[2 * row3..]);
                        dn
                    };
                    let up = (y0 > 0).then(|| halo_row(b - 1, 1, y0 - 1));
                    let down = (y1 < h).then(|| halo_row(b + 1, 0, y1));
                    let mut sums = StepSums::default();
                    // row y0 + k of the band: finish the last step and form the new d there
                    let advance = |k: usize,
                                   xb: &mut [f32],
                                   rb: &mut [f32],
                                   db: &mut [f32],
                                   qb: &[f32],
                                   sums: &mut StepSums| {
                        let rows = k * row3..(k + 1) * row3;
                        let y = y0 + k;
                        let rk = &mut rb[rows.clone()];
                        advance_row(w, prev, m(y), Some(&mut xb[rows.clone()]), rk, &mut db[rows.clone()], &qb[rows]);
                        for c in 0..3 {
                            let rc = &rk[c * w..(c + 1) * w];
                            sums.rz[c] += dot_weighted(rc, m(y));
                            sums.rr[c] += dot(rc, rc);
                        }
                    };
                    advance(0, xb, rb, db, qb, &mut sums);
                    for y in y0..y1 {
                        let k = y - y0;
                        if y + 1 < y1 {
                            advance(k + 1, xb, rb, db, qb, &mut sums);
                        }
                        let (db, rb): (&[f32], &[f32]) = (db, rb);
                        let row = |k: usize| &db[k * row3..(k + 1) * row3];
                        let above = if y == y0 { up.as_deref() } else { Some(row(k - 1)) };
                        let below = if y + 1 == y1 { down.as_deref() } else { Some(row(k + 1)) };
                        let qrow = &mut qb[k * row3..(k + 1) * row3];
                        for c in 0..3 {
                            let cw = c * w..(c + 1) * w;
                            let o = &mut qrow[cw.clone()];
                            let (u, dn) = (above.map(|v| &v[cw.clone()]), below.map(|v| &v[cw.clone()]));
                            stencil_row(wts, a2, w, y, u, &row(k)[cw.clone()], dn, o);
                            sums.dad[c] += dot(&row(k)[cw.clone()], o);
                            sums.rzq[c] += dot3(&rb[k * row3..][cw.clone()], o, m(y));
                            sums.qzq[c] += dot_weighted(o, m(y));
                        }
                    }
                    sums
                })
                .collect();
            let s = parts.into_iter().fold(StepSums::default(), StepSums::add);
            // (2) the step length, and the β of the next direction from r·M⁻¹r after the step
            let mut a = [0.0f32; 3];
            let mut beta = [0.0f32; 3];
            for c in 0..3 {
                moving[c] = moving[c] && s.rr[c] > tol2 * bnorm2[c] && s.rz[c] > 0.0 && s.dad[c] > 0.0;
                if !moving[c] {
                    continue;
                }
                let ac = s.rz[c] / s.dad[c];
                let rz_next = s.rz[c] - 2.0 * ac * s.rzq[c] + ac * ac * s.qzq[c];
                a[c] = ac as f32;
                beta[c] = if rz_next > 0.0 { (rz_next / s.rz[c]) as f32 } else { 0.0 };
            }
            prev = Some((a, beta));
        }
        drop(halo);
        // (3) the last step's x += a·d
        if let Some((a, _)) = prev.filter(|(a, _)| a.iter().any(|&v| v != 0.0)) {
            let dd: &RowPlanar = d;
            x.data.par_chunks_mut(BAND * row3).zip(dd.data.par_chunks(BAND * row3)).for_each(|(xb, db)| {
                for (i, (xr, dr)) in xb.chunks_exact_mut(w).zip(db.chunks_exact(w)).enumerate() {
                    let ac = a[i % 3];
                    for (xi, &di) in xr.iter_mut().zip(dr) {
                        *xi += ac * di;
                    }
                }
            });
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    /// Each CG step is the textbook Jacobi-preconditioned CG step (Shewchuk 1994, B2), written
    /// here in f64 from the weighted energy itself: after k = 1…7 steps from the same start the
    /// iterates agree to f32 precision — the one-pass step, whose β comes from an expansion of
    /// the next r·M⁻¹r, takes the same steps, across bands (the last one a single row) and on
    /// channels of different scales.
    #[test]
    fn cg_steps_are_the_textbook_pcg_steps() {
        let (w, h) = (13, 2 * BAND + 1);
        let n = w * h;
        let mut s = IndependentSampler::new(3, 9);
        let mut rnd = |lo: f64, hi: f64| lo + (hi - lo) * s.next_1d() as f64;
        let planes: Vec<[Vec<f64>; 4]> = (0..3)
            .map(|c| std::array::from_fn(|_| (0..n).map(|_| rnd(-1.0, 1.0) * [1.0, 30.0, 0.02][c]).collect()))
            .collect();
        let mut wts = Weights::ones(w, h);
        for v in [&mut wts.g, &mut wts.x, &mut wts.y] {
            v.iter_mut().for_each(|x| *x *= rnd(0.01, 10.0) as f32);
        }
        let alpha = 0.3f64;
        let a2 = alpha * alpha;
        let rp = |k: usize| RowPlanar::from_planes([&planes[0][k], &planes[1][k], &planes[2][k]], w, h);
        let p = Problem { alpha: alpha as f32, primal: rp(0), dx: rp(1), dy: rp(2) };
        let (g, wx, wy) = (|i: usize| wts.g[i] as f64, |i: usize| wts.x[i] as f64, |i: usize| wts.y[i] as f64);
        // the energy's normal equations: A v and b, and diag(A)
        let apply = |v: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let (xi, yi) = (i % w, i / w);
                    let mut o = a2 * g(i) * v[i];
                    if xi + 1 < w {
                        o += wx(i) * (v[i] - v[i + 1]);
                    }
                    if xi > 0 {
                        o += wx(i - 1) * (v[i] - v[i - 1]);
                    }
                    if yi + 1 < h {
                        o += wy(i) * (v[i] - v[i + w]);
                    }
                    if yi > 0 {
                        o += wy(i - w) * (v[i] - v[i - w]);
                    }
                    o
                })
                .collect()
        };
        let diag: Vec<f64> = (0..n)
            .map(|i| {
                let (xi, yi) = (i % w, i / w);
                a2 * g(i) + wx(i) + wy(i) + if xi > 0 { wx(i - 1) } else { 0.0 } + if yi > 0 { wy(i - w) } else { 0.0 }
            })
            .collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        for steps in 1..=7 {
            let mut x = rp(3);
            p.solve(&wts, &mut x, steps, 1e-12, &|| false);
            for (c, [pg, gx, gy, x0]) in planes.iter().enumerate() {
                let b: Vec<f64> = (0..n)
                    .map(|i| {
                        let mut o = a2 * g(i) * pg[i] - wx(i) * gx[i] - wy(i) * gy[i];
                        if i % w > 0 {
                            o += wx(i - 1) * gx[i - 1];
                        }
                        if i >= w {
                            o += wy(i - w) * gy[i - w];
                        }
                        o
                    })
                    .collect();
                let mut v: Vec<f64> = x0.iter().map(|&a| a as f32 as f64).collect();
                let mut r: Vec<f64> = b.iter().zip(apply(&v)).map(|(b, a)| b - a).collect();
                let mut z: Vec<f64> = r.iter().zip(&diag).map(|(r, d)| r / d).collect();
                let mut d = z.clone();
                let mut rz = dot(&r, &z);
                for _ in 0..steps {
                    let q = apply(&d);
                    let a = rz / dot(&d, &q);
                    v.iter_mut().zip(&d).for_each(|(v, d)| *v += a * d);
                    r.iter_mut().zip(&q).for_each(|(r, q)| *r -= a * q);
                    z = r.iter().zip(&diag).map(|(r, d)| r / d).collect();
                    let rz_new = dot(&r, &z);
                    d = z.iter().zip(&d).map(|(z, d)| z + rz_new / rz * d).collect();
                    rz = rz_new;
                }
                let got = x.plane(c);
                let scale = v.iter().fold(0.0f64, |m, a| m.max(a.abs()));
                for i in 0..n {
                    assert!(
                        (got[i] - v[i]).abs() < 1e-4 * scale,
                        "{steps} steps, channel {c}, pixel {i}: {} vs textbook {}",
                        got[i],
                        v[i]
                    );
                }
            }
        }
    }

    /// With arbitrary positive row weights (as IRLS gives), CG reaches the minimiser of the
    /// weighted problem, across bands (whose neighbours' rows each pass recomputes): the one a plain f64 Gauss–Seidel iteration on the same energy,
    /// written from the energy itself, converges to.
    #[test]
    fn weighted_cg_reaches_the_weighted_minimiser() {
        let (w, h) = (21, 2 * BAND + 1); // the last band one row: its first row is its last
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
