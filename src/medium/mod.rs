//! Participating media: homogeneous volumes inside closed meshes (a material's Volume output,
//! Cycles' rule: the mesh's surface is the medium's boundary), with the radiative transfer
//! of pbrt-v4's and Cycles' volume path tracers in closed form.
//!
//! A medium has per-channel scattering σs and absorption σa coefficients (per unit of world
//! distance), extinction σt = σs + σa, a Henyey–Greenstein phase function and an emission
//! coefficient ε (radiance added per unit distance). Along a ray segment of length d:
//!
//! * transmittance T(t) = exp(−σt t) per channel;
//! * emission ∫₀ᵈ T(t) ε dt = ε (1 − exp(−σt d)) / σt, added in closed form;
//! * a free-flight distance t is drawn by spectral MIS over the three channels (a channel c
//!   picked uniformly, t ~ σt_c exp(−σt_c t)), with density p(t) = ⅓ Σ_c σt_c T_c(t); a
//!   scattering event at t < d weighs σs T(t) / p(t), passing the segment weighs
//!   T(d) / P(t ≥ d) with P = ⅓ Σ_c T_c(d) — exact (weight σs/σt, 1) for a grey medium.
//!
//! A medium may also have a heterogeneous part (`Field`): coefficients per unit density
//! scaled by a density field (a procedural texture read at the point's Generated or Object
//! coordinates), tracked by `heterogeneous.rs` (delta and ratio tracking under a majorant).
//!
//! Which media a ray is in is a [`MediumStack`]: the materials whose boundaries it entered
//! (through the front of the surface) and has not left; overlapping media add their
//! coefficients, as Cycles' volume stack does.

pub mod heterogeneous;
pub mod phase;
pub mod subsurface;

pub use phase::{HenyeyGreenstein, Phase};

use crate::math::Spectrum;
use glam::Vec3;

/// A homogeneous medium's coefficients (per unit world distance) and phase function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Medium {
    pub sigma_s: Spectrum,
    pub sigma_a: Spectrum,
    /// Emission coefficient ε: radiance added per unit distance.
    pub emission: Spectrum,
    pub phase: Phase,
    /// The heterogeneous part, added to the constant coefficients above (None: homogeneous).
    pub field: Option<Field>,
}

/// Coefficients per unit density, scaled at each point by a density field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Field {
    pub density: Density,
    pub sigma_s: Spectrum,
    pub sigma_a: Spectrum,
}

/// A density field: texture `texture` (a procedural pattern and the graph after it) read at a
/// point's coordinates — Object (`world_to_object`, row-major 3×4) and Generated (the object
/// point scaled and offset per axis, `generated`: scale xyz, offset xyz: the texture space) —,
/// its value's first channel; `max` bounds it from above (the majorant's factor; values
/// below 0 count as 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Density {
    pub texture: u32,
    pub world_to_object: [f32; 12],
    pub generated: [f32; 6],
    pub max: f32,
}

impl Density {
    /// (Object, Generated) coordinates of world point `p`.
    #[inline]
    pub fn coordinates(&self, p: Vec3) -> (Vec3, Vec3) {
        let m = &self.world_to_object;
        let o = Vec3::new(
            m[0] * p.x + m[1] * p.y + m[2] * p.z + m[3],
            m[4] * p.x + m[5] * p.y + m[6] * p.z + m[7],
            m[8] * p.x + m[9] * p.y + m[10] * p.z + m[11],
        );
        let g = &self.generated;
        (o, Vec3::new(o.x * g[0] + g[3], o.y * g[1] + g[4], o.z * g[2] + g[5]))
    }
}

/// The outcome of free-flight sampling along a segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FreeFlight {
    /// Scattered at distance `t`; the path throughput is multiplied by `weight` = σs T(t) / p(t).
    Scatter { t: f32, weight: Spectrum },
    /// Reached the segment's end; throughput × `weight` = T(d) / P(t ≥ d).
    Pass { weight: Spectrum },
}

impl Medium {
    /// Extinction σt = σs + σa.
    #[inline]
    pub fn sigma_t(&self) -> Spectrum {
        self.sigma_s + self.sigma_a
    }

    /// Whether light along a segment is touched at all (extinction or emission).
    #[inline]
    pub fn is_vacuum(&self) -> bool {
        self.sigma_t().max_element() <= 0.0
            && self.emission.max_element() <= 0.0
            && self.field.is_none_or(|f| (f.sigma_s + f.sigma_a).max_element() <= 0.0 || f.density.max <= 0.0)
    }

    /// The coefficients vary from point to point (`field`).
    #[inline]
    pub fn is_heterogeneous(&self) -> bool {
        self.field.is_some()
    }

    /// (σs, σa) where the density field is `d`.
    #[inline]
    pub fn coefficients_at(&self, d: f32) -> (Spectrum, Spectrum) {
        match &self.field {
            Some(f) => (self.sigma_s + f.sigma_s * d.max(0.0), self.sigma_a + f.sigma_a * d.max(0.0)),
            None => (self.sigma_s, self.sigma_a),
        }
    }

    /// The majorant μ: a bound of σt over every channel and point.
    #[inline]
    pub fn majorant(&self) -> f32 {
        let (s, a) = self.coefficients_at(self.field.map_or(0.0, |f| f.density.max));
        (s + a).max_element()
    }

    /// Transmittance over distance `d` (per channel; 0 over an infinite distance in an
    /// extinguishing channel, 1 in a clear one).
    #[inline]
    pub fn transmittance(&self, d: f32) -> Spectrum {
        let st = self.sigma_t();
        Spectrum::new(tr(st.x, d), tr(st.y, d), tr(st.z, d))
    }

    /// The emission gathered along a segment of length `d`: ∫₀ᵈ T(t) ε dt per channel
    /// (ε·d where σt = 0; an infinite segment of a clear channel gathers nothing, as a
    /// medium does not fill the world).
    #[inline]
    pub fn emitted(&self, d: f32) -> Spectrum {
        let (st, e) = (self.sigma_t(), self.emission);
        let one = |s: f32, e: f32| {
            if e <= 0.0 {
                0.0
            } else if !d.is_finite() {
                if s > 0.0 {
                    e / s
                } else {
                    0.0
                }
            } else if s * d < 1e-4 {
                e * d * (1.0 - 0.5 * s * d)
            } else {
                e * -(-s * d).exp_m1() / s
            }
        };
        Spectrum::new(one(st.x, e.x), one(st.y, e.y), one(st.z, e.z))
    }

    /// Free-flight sampling over a segment of length `d` (infinite for a ray that leaves
    /// the scene) with one primary sample `u` (its first third picks the red channel, and so
    /// on; the rest of it is the distance's).
    #[inline]
    pub fn sample_distance(&self, u: f32, d: f32) -> FreeFlight {
        let st = self.sigma_t();
        let x = (u * 3.0).min(2.999_999_8);
        let c = x as usize;
        let u = x - c as f32;
        let s = st[c];
        let t = if s > 0.0 { -(-u).ln_1p() / s } else { f32::INFINITY };
        if t < d {
            let tr = self.transmittance(t);
            let pdf = (st * tr).element_sum() / 3.0;
            FreeFlight::Scatter { t, weight: if pdf > 0.0 { self.sigma_s * tr / pdf } else { Spectrum::ZERO } }
        } else {
            let tr = self.transmittance(d);
            let p = tr.element_sum() / 3.0;
            FreeFlight::Pass { weight: if p > 0.0 { tr / p } else { Spectrum::ZERO } }
        }
    }

    /// The density of [`Medium::sample_distance`] scattering at `t` (per unit length), and
    /// its probability of passing a segment of length `d`.
    #[inline]
    pub fn distance_pdf(&self, t: f32) -> f32 {
        (self.sigma_t() * self.transmittance(t)).element_sum() / 3.0
    }

    #[inline]
    pub fn pass_probability(&self, d: f32) -> f32 {
        self.transmittance(d).element_sum() / 3.0
    }
}

#[inline]
fn tr(sigma: f32, d: f32) -> f32 {
    if sigma <= 0.0 {
        1.0
    } else {
        (-sigma * d).exp()
    }
}

/// Analytic lights a segment in a medium crosses (at most `MAX_CROSSINGS`; more are left
/// out), and the flight's throughput where it passed each (`Scene::fly`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Crossings {
    pub n: usize,
    pub light: [u32; MAX_CROSSINGS],
    pub t: [f32; MAX_CROSSINGS],
    pub le: [Spectrum; MAX_CROSSINGS],
    pub pdf: [f32; MAX_CROSSINGS],
    pub weight: [Spectrum; MAX_CROSSINGS],
}

/// Lights crossed along one segment in a medium that are counted.
pub const MAX_CROSSINGS: usize = 8;

impl Crossings {
    #[inline]
    pub fn push(&mut self, light: u32, t: f32, le: Spectrum, pdf: f32) {
        if self.n < MAX_CROSSINGS {
            (self.light[self.n], self.t[self.n], self.le[self.n], self.pdf[self.n]) = (light, t, le, pdf);
            self.n += 1;
        }
    }
}

/// A free flight through a segment's medium (`Scene::fly`): where it ends, and the emission
/// gathered (throughput-weighted).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flight {
    pub free: FreeFlight,
    pub emitted: Spectrum,
}

/// The most media a ray may be inside at once; entering one more leaves it out (with the
/// nested glass-liquid-ice of real scenes far below).
pub const MAX_NESTED_MEDIA: usize = 4;

/// The media a ray is inside: the materials (indices) whose boundaries it entered and has
/// not left, in entering order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MediumStack {
    ids: [u32; MAX_NESTED_MEDIA],
    len: u8,
}

impl MediumStack {
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    #[inline]
    pub fn ids(&self) -> &[u32] {
        &self.ids[..self.len as usize]
    }

    /// Entered the boundary of material `m`'s medium.
    #[inline]
    pub fn enter(&mut self, m: u32) {
        if (self.len as usize) < MAX_NESTED_MEDIA {
            self.ids[self.len as usize] = m;
            self.len += 1;
        }
    }

    /// Left the boundary of material `m`'s medium (the last entry of it; a boundary left
    /// that was never entered — an open mesh, a camera placed inside — changes nothing).
    #[inline]
    pub fn leave(&mut self, m: u32) {
        if let Some(i) = self.ids().iter().rposition(|&x| x == m) {
            self.ids.copy_within(i + 1..self.len as usize, i);
            self.len -= 1;
        }
    }

    /// Crossed the boundary of material `m`'s medium, from its front (outside) or its back.
    #[inline]
    pub fn cross(&mut self, m: u32, from_front: bool) {
        if from_front {
            self.enter(m)
        } else {
            self.leave(m)
        }
    }
}

/// The medium of a stack: the sum of the coefficients of the media in it (`media[m]` the
/// medium of material m), with a phase function of the scattering-weighted mean anisotropy
/// (exact for one medium, and for overlapping media of one anisotropy). None for a stack
/// of no medium or only clear ones.
pub fn combined(stack: &MediumStack, media: &[Option<Medium>]) -> Option<Medium> {
    let mut it = stack.ids().iter().filter_map(|&m| media.get(m as usize).copied().flatten());
    let first = it.next()?;
    let mut sum = first;
    let scattering = |m: &Medium| m.sigma_s.element_sum() + m.field.map_or(0.0, |f| f.sigma_s.element_sum());
    let mut g_weight = 0.0;
    let mut several = false;
    for m in it {
        if !several {
            g_weight = scattering(&first) * first.phase.mean_cosine();
            several = true;
        }
        sum.sigma_s += m.sigma_s;
        sum.sigma_a += m.sigma_a;
        sum.emission += m.emission;
        g_weight += scattering(&m) * m.phase.mean_cosine();
        // (one density field per ray: a second one overlapping it counts at its bound, too
        // dense — docs/limits.md)
        match (sum.field, m.field) {
            (None, f) => sum.field = f,
            (Some(_), Some(f)) => {
                sum.sigma_s += f.sigma_s * f.density.max;
                sum.sigma_a += f.sigma_a * f.density.max;
            }
            _ => {}
        }
    }
    let s = sum.sigma_s.element_sum() + sum.field.map_or(0.0, |f| f.sigma_s.element_sum());
    if several {
        // (overlapping media: Henyey–Greenstein of their scattering-weighted mean cosine)
        sum.phase = Phase::hg(if s > 0.0 { g_weight / s } else { 0.0 });
    }
    (!sum.is_vacuum()).then_some(sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::{IndependentSampler, Sampler};

    fn chromatic() -> Medium {
        Medium {
            sigma_s: Spectrum::new(0.8, 0.3, 0.05),
            sigma_a: Spectrum::new(0.1, 0.4, 0.9),
            emission: Spectrum::new(0.5, 0.0, 2.0),
            phase: Phase::hg(0.3),
            field: None,
        }
    }

    /// Free-flight sampling is unbiased for the two integrals it estimates over a slab of
    /// depth d: E[weight · 1{scatter}] = ∫₀ᵈ σs T dt = σs (1 − T(d)) / σt, and
    /// E[weight · 1{pass}] = T(d), per channel (the collision estimator's two terms).
    #[test]
    fn free_flight_sampling_is_unbiased_per_channel() {
        let m = chromatic();
        let n = 400_000;
        for d in [0.3f32, 2.0, 9.0] {
            let mut s = IndependentSampler::new(5, 0);
            let (mut scatter, mut pass) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
            let (mut scatter2, mut pass2) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
            for _ in 0..n {
                match m.sample_distance(s.next_1d(), d) {
                    FreeFlight::Scatter { t, weight } => {
                        assert!(t >= 0.0 && t < d);
                        scatter += weight.as_dvec3();
                        scatter2 += (weight * weight).as_dvec3();
                    }
                    FreeFlight::Pass { weight } => {
                        pass += weight.as_dvec3();
                        pass2 += (weight * weight).as_dvec3();
                    }
                }
            }
            let st = m.sigma_t().as_dvec3();
            let t_d = (-st * d as f64).exp();
            let want_scatter = m.sigma_s.as_dvec3() * (glam::DVec3::ONE - t_d) / st;
            for (name, sum, sum2, want) in [("scatter", scatter, scatter2, want_scatter), ("pass", pass, pass2, t_d)] {
                let mean = sum / n as f64;
                let sd = ((sum2 / n as f64 - mean * mean) / n as f64).max(glam::DVec3::splat(1e-12)).powf(0.5);
                for c in 0..3 {
                    assert!(
                        (mean[c] - want[c]).abs() < 5.0 * sd[c] + 1e-6,
                        "d = {d}, {name}, channel {c}: {} against {} (σ {})",
                        mean[c],
                        want[c],
                        sd[c]
                    );
                }
            }
        }
    }

    /// The closed forms against a fine midpoint rule: transmittance and gathered emission.
    #[test]
    fn transmittance_and_emission_match_quadrature() {
        let m = chromatic();
        let d = 1.7f32;
        let n = 100_000;
        let mut e = glam::DVec3::ZERO;
        for i in 0..n {
            let t = (i as f64 + 0.5) / n as f64 * d as f64;
            e += (m.emission.as_dvec3()) * (-m.sigma_t().as_dvec3() * t).exp() * (d as f64 / n as f64);
        }
        let got = m.emitted(d).as_dvec3();
        assert!((got - e).abs().max_element() < 1e-4, "emission {got:?} against {e:?}");
        let tr = m.transmittance(d);
        let want = (-m.sigma_t() * d).exp();
        assert!((tr - want).abs().max_element() < 1e-6);
        // a channel with no extinction gathers ε·d; a clear infinite ray gathers nothing
        let clear = Medium { sigma_a: Spectrum::ZERO, sigma_s: Spectrum::ZERO, ..m };
        assert!((clear.emitted(2.0) - m.emission * 2.0).abs().max_element() < 1e-5);
        assert_eq!(clear.emitted(f32::INFINITY), Spectrum::ZERO);
        assert_eq!(m.transmittance(f32::INFINITY), Spectrum::ZERO);
    }

    /// The stack: nested media entered and left in any order; leaving one never entered
    /// changes nothing; overlapping media add.
    #[test]
    fn stack_enters_leaves_and_adds() {
        let mut s = MediumStack::default();
        s.cross(3, true);
        s.cross(5, true);
        s.cross(3, false);
        assert_eq!(s.ids(), &[5]);
        s.cross(7, false);
        assert_eq!(s.ids(), &[5]);
        s.cross(5, true);
        let media = {
            let mut v = vec![None; 8];
            v[5] = Some(chromatic());
            v
        };
        let c = combined(&s, &media).unwrap();
        assert!((c.sigma_t() - 2.0 * chromatic().sigma_t()).abs().max_element() < 1e-6);
        assert!((c.phase.mean_cosine() - 0.3).abs() < 1e-6);
        assert!(combined(&MediumStack::default(), &media).is_none());
        for _ in 0..10 {
            s.enter(1); // past MAX_NESTED_MEDIA: left out, never a panic
        }
        assert_eq!(s.ids().len(), MAX_NESTED_MEDIA);
    }
}
