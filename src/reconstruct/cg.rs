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
//! two passes over the image: the new direction d = M⁻¹r + βd with A·d and d·A·d; then
//! x += a·d and r −= a·A·d with r·M⁻¹r. IRLS's reweighting and the CG's set-up are one pass
//! too (`solve_reweighted_in`): the residuals at x give both the new row weights and
//! r = b − A·x. Every pass runs over bands of `BAND` rows in parallel and sums its dot
//! products band by band in order, so the result does not depend on the thread count.
//! (Measured at 1920×1080 on 2 cores, docs/benchmarks.md: 12–14% faster than three passes
//! per step and a separate weights pass; recomputing A·d in the second pass instead of
//! storing it saved bytes but cost more arithmetic, 5%.)

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

    /// The residual r = b − A·x of the last set-up or step (for tests).
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
                        for (i, bi) in bb.iter_mut().enumerate() {
                            *bi = a2 * gr[i] * p[i] - xr[i] * gx[i] + wy_up[i] * gu[i] - yr[i] * gy[i];
                        }
                        for (bi, (&k, &v)) in bb[1..].iter_mut().zip(xr.iter().zip(gx)) {
                            *bi += k * v;
                        }
                        s[0][c] += dot(&bb, &bb);
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
    /// given). Each step is two passes: (1) d = M⁻¹r + βd (β = 0 first), A·d and d·A·d, (2)
    /// x += a·d, r −= a·A·d and r·M⁻¹r, r·r. In (1) each band needs the new d one row beyond its
    /// ends, which its neighbours own and overwrite meanwhile: it computes those rows itself
    /// from copies of the old ones (every band's first and last rows, taken before the pass),
    /// so no band reads a row another is writing.
    #[allow(clippy::too_many_arguments)]
    fn iterate(
        &self,
        ws: &mut Workspace,
        wts: &Weights,
        x: &mut RowPlanar,
        bnorm2: [f64; 3],
        mut rz: [f64; 3],
        iters: usize,
        tol: f64,
        stop: &(dyn Fn() -> bool + Sync),
    ) {
        let Workspace { dinv, r, d, ad: adv } = ws;
        let (w, h) = (self.width(), self.height());
        let a2 = self.alpha * self.alpha;
        let tol2 = tol * tol;
        let mut rr = [f64::INFINITY; 3];
        let mut beta: Option<[f32; 3]> = None; // None: the first direction, M⁻¹r
        for _ in 0..iters {
            let moving: [bool; 3] = std::array::from_fn(|c| rr[c] > tol2 * bnorm2[c] && rz[c] > 0.0);
            if stop() || !moving.iter().any(|&m| m) {
                break;
            }
            // (1) the new direction, and d·A·d. Each band's first and last old rows, copied
            // first: the neighbours' view of them while the band overwrites its own.
            let nb = h.div_ceil(BAND);
            let row3 = 3 * w;
            let mut halo = vec![0.0f32; if beta.is_some() { nb * 2 * row3 } else { 0 }];
            if beta.is_some() {
                let dd: &RowPlanar = d;
                halo.par_chunks_mut(2 * row3).enumerate().for_each(|(b, hb)| {
                    let (y0, y1) = (b * BAND, ((b + 1) * BAND).min(h));
                    hb[..row3].copy_from_slice(&dd.data[y0 * row3..(y0 + 1) * row3]);
                    hb[row3..].copy_from_slice(&dd.data[(y1 - 1) * row3..y1 * row3]);
                });
            }
            let (r_ref, dinv_ref, halo_ref): (&RowPlanar, &[f32], &[f32]) = (r, dinv, &halo);
            // row y of the new d (3 channels) from row y of the old one
            let new_row = |y: usize, old: &[f32], out: &mut [f32]| {
                let m = &dinv_ref[y * w..(y + 1) * w];
                for (c, o) in out.chunks_exact_mut(w).enumerate() {
                    let rr = r_ref.row(y, c);
                    match beta {
                        None => o.iter_mut().zip(rr).zip(m).for_each(|((o, &ri), &mi)| *o = ri * mi),
                        Some(be) => o
                            .iter_mut()
                            .zip(rr)
                            .zip(m.iter().zip(&old[c * w..(c + 1) * w]))
                            .for_each(|((o, &ri), (&mi, &di))| *o = ri * mi + be[c] * di),
                    }
                }
            };
            let empty: &[f32] = &[];
            let dad = sum3(
                d.data
                    .par_chunks_mut(BAND * row3)
                    .zip(adv.data.par_chunks_mut(BAND * row3))
                    .enumerate()
                    .map(|(b, (db, adb))| {
                        let (y0, y1) = (b * BAND, ((b + 1) * BAND).min(h));
                        let old = |y: usize| -> &[f32] {
                            if beta.is_none() {
                                empty
                            } else if y + 1 == y0 {
                                &halo_ref[(2 * b - 1) * row3..2 * b * row3]
                            } else {
                                &halo_ref[2 * (b + 1) * row3..(2 * (b + 1) + 1) * row3]
                            }
                        };
                        // rows y − 1, y, y + 1 of the new d
                        let (mut up, mut cur, mut down) = (vec![0.0f32; row3], vec![0.0f32; row3], vec![0.0f32; row3]);
                        if y0 > 0 {
                            new_row(y0 - 1, old(y0 - 1), &mut up);
                        }
                        new_row(y0, if beta.is_some() { &db[..row3] } else { empty }, &mut cur);
                        let mut sums = [0.0f64; 3];
                        for y in y0..y1 {
                            if y + 1 < y1 {
                                let k = y + 1 - y0;
                                let o: &[f32] = if beta.is_some() { &db[k * row3..(k + 1) * row3] } else { empty };
                                new_row(y + 1, o, &mut down);
                            } else if y + 1 < h {
                                new_row(y + 1, old(y + 1), &mut down);
                            }
                            for c in 0..3 {
                                let cw = c * w..(c + 1) * w;
                                let (u, dn) =
                                    ((y > 0).then(|| &up[cw.clone()]), (y + 1 < h).then(|| &down[cw.clone()]));
                                let o = &mut adb[(y - y0) * row3 + c * w..(y - y0) * row3 + (c + 1) * w];
                                stencil_row(wts, a2, w, y, u, &cur[cw.clone()], dn, o);
                                sums[c] += dot(&cur[cw.clone()], o);
                            }
                            // the old row y is read by no one any more
                            db[(y - y0) * row3..(y - y0 + 1) * row3].copy_from_slice(&cur);
                            std::mem::swap(&mut up, &mut cur);
                            std::mem::swap(&mut cur, &mut down);
                        }
                        sums
                    })
                    .collect::<Vec<_>>(),
            );
            drop(halo);
            let step: [f32; 3] =
                std::array::from_fn(|c| if moving[c] && dad[c] > 0.0 { (rz[c] / dad[c]) as f32 } else { 0.0 });
            // (2) x += a·d, r −= a·A·d; Σ r·M⁻¹r and Σ r·r
            let (d_ref, dinv_ref, adv_ref): (&RowPlanar, &[f32], &RowPlanar) = (d, dinv, adv);
            let sums: Vec<[[f64; 3]; 2]> = x
                .data
                .par_chunks_mut(BAND * row3)
                .zip(r.data.par_chunks_mut(BAND * row3))
                .enumerate()
                .map(|(b, (xb, rb))| {
                    let mut s = [[0.0f64; 3]; 2];
                    for (k, (xrows, rrows)) in xb.chunks_exact_mut(row3).zip(rb.chunks_exact_mut(row3)).enumerate() {
                        let y = b * BAND + k;
                        let m = &dinv_ref[y * w..(y + 1) * w];
                        for (c, (xr, rr)) in xrows.chunks_exact_mut(w).zip(rrows.chunks_exact_mut(w)).enumerate() {
                            let a = step[c];
                            for ((xi, ri), (&di, &adi)) in
                                xr.iter_mut().zip(rr.iter_mut()).zip(d_ref.row(y, c).iter().zip(adv_ref.row(y, c)))
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
            beta = Some(std::array::from_fn(|c| if rz[c] > 0.0 { (rz_new[c] / rz[c]) as f32 } else { 0.0 }));
            rz = rz_new;
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
