//! Which light a shading point samples for next-event estimation: probabilities that follow
//! what each light contributes *at that point*, in the spirit of Cycles' light tree
//! (Conty Estevez & Kulla 2018) without the tree: every entry's importance is an estimate of
//! the irradiance it sends to the point, and the point picks an entry ∝ importance.
//!
//! Entries: each analytic light (point, spot, area, sun), each group of emissive triangles
//! of one material (its triangles then chosen ∝ power inside the group), and the world.
//! Importance at p (luminance, W/m²):
//! * point / sphere of power Φ: Φ/(4π·max(d², r²)) × the spot's falloff towards p;
//! * area light (one-sided, power Φ = π·L·A): Φ/(π·max(d², A)) × a bound of the cosine at
//!   the light (0 behind its plane);
//! * triangle group (two-sided, Φ = 2π·L·A): Φ/(2π·max(dist(p, bounds)², A)) ;
//! * sun: its irradiance; the world (an HDRI): π × its mean radiance. A world of one
//!   colour is not an entry: BSDF sampling alone finds it with less variance (scene/mod.rs).
//!
//! The distance-free terms (sun, world) no longer grow with the scene's size, as the former
//! power-proportional choice did (it gave a sun or a dim world most of the samples on a large
//! ground plane). With more than `SPATIAL_MAX` entries the importances are evaluated once, at
//! the centre of the scene's bounds (a global distribution; O(log N) per sample); so they are
//! with a single entry, where the choice is the same everywhere.
//!
//! Measured (pt and gdpt with NEE, 48², relMSE after 1 s against PT at 4096 spp, 3 seeds,
//! 2026-12-01): the built-in `lights` scene (mesh, area, sphere, spot, sun, world) 2.7× lower
//! for both (pt 4.6e-3 → 1.7e-3, gdpt 2.2e-3 → 8.4e-4); one-light scenes (Cornell, bulb)
//! 2.4e-4 → 2.7e-4 and 0.114 → 0.130 for pt, within what 1-second runs vary by here.
//!
//! `sample` and `pmf` evaluate the same function, so MIS weights and the shift mapping's
//! re-evaluated pdfs stay exact: every caller passes the shading point the light is
//! sampled from.

use super::light::{Light, LightShape};
use crate::distribution::Distribution1D;
use crate::math::luminance;
use glam::Vec3;
use std::f32::consts::PI;

/// Up to this many entries the importances are evaluated at every shading point.
pub const SPATIAL_MAX: usize = 64;

#[derive(Clone, Debug)]
enum Kind {
    Sphere {
        center: Vec3,
        r2: f32,
        spot: Option<super::light::Spot>,
    },
    Planar {
        center: Vec3,
        normal: Vec3,
        half_diagonal: f32,
        area: f32,
    },
    /// Distance-free: sun and world.
    Constant,
    Triangles {
        lo: Vec3,
        hi: Vec3,
        area: f32,
        members: Vec<u32>,
        dist: Distribution1D,
    },
}

#[derive(Clone, Debug)]
struct Entry {
    kind: Kind,
    /// The light index of a single-light entry (unused for triangle groups).
    light: u32,
    /// Power (luminance) for the kinds with a distance term, irradiance for `Constant`.
    power: f32,
}

impl Entry {
    /// The importance at p; `oriented` false leaves out the factors of direction (spot cone,
    /// the facing of an area light) — the global choice's weights, evaluated at one point
    /// for the whole scene, must not drop a light that merely faces away from that point.
    #[inline]
    fn importance(&self, p: Vec3, oriented: bool) -> f32 {
        match &self.kind {
            Kind::Constant => self.power,
            Kind::Sphere { center, r2, spot } => {
                let to = p - *center;
                let d2 = to.length_squared();
                let att = if oriented { spot.map_or(1.0, |s| s.attenuation(to.normalize_or_zero())) } else { 1.0 };
                self.power * att / (4.0 * PI * d2.max(*r2).max(1e-12))
            }
            Kind::Planar { center, normal, half_diagonal, area } => {
                let to = p - *center;
                let d2 = to.length_squared();
                let cos_bound = if oriented {
                    let h = to.dot(*normal);
                    if h <= 0.0 {
                        return 0.0; // behind (or in) the plane of a one-sided emitter
                    }
                    ((h + half_diagonal) / d2.sqrt().max(1e-12)).min(1.0)
                } else {
                    1.0
                };
                self.power * cos_bound / (PI * d2.max(*area).max(1e-12))
            }
            Kind::Triangles { lo, hi, area, .. } => {
                let d = (*lo - p).max(p - *hi).max(Vec3::ZERO);
                self.power / (2.0 * PI * d.length_squared().max(*area).max(1e-12))
            }
        }
    }
}

#[derive(Clone, Debug)]
pub struct LightSelector {
    entries: Vec<Entry>,
    /// For each light index (the world last): its entry and its probability inside it.
    of_light: Vec<(u32, f32)>,
    /// Entries ∝ importance at the bounds' centre, used when there are too many entries
    /// (and for `is_empty`).
    global: Distribution1D,
    spatial: bool,
}

impl LightSelector {
    /// `lights` (emissive triangles included, `tri_material[prim]` their material,
    /// `emission_scale[material]` a textured emitter's mean) and the world's irradiance-like
    /// weight π·L̄ (0 for a black world, which is then never chosen).
    pub fn new(
        lights: &[Light],
        tri_material: &[u32],
        tri_positions: &[[Vec3; 3]],
        areas: &[f32],
        emission_scale: &[f32],
        world: f32,
        bounds_center: Vec3,
    ) -> LightSelector {
        let mut entries = Vec::new();
        let mut of_light = vec![(u32::MAX, 0.0f32); lights.len() + 1];
        // triangle groups by material: (entry index, member lights, their powers)
        let mut groups: std::collections::BTreeMap<u32, (Vec<u32>, Vec<f32>)> = Default::default();
        for (i, l) in lights.iter().enumerate() {
            let lum = luminance(l.emission).max(0.0);
            let entry = match &l.shape {
                LightShape::Triangle { prim } => {
                    let m = tri_material[*prim as usize];
                    let power = lum * 2.0 * PI * areas[*prim as usize] * emission_scale[m as usize];
                    let g = groups.entry(m).or_default();
                    g.0.push(i as u32);
                    g.1.push(power);
                    continue;
                }
                LightShape::Sphere { center, radius, spot, .. } => Entry {
                    kind: Kind::Sphere { center: *center, r2: radius * radius, spot: *spot },
                    light: i as u32,
                    power: l.power_estimate(1.0, 0.0),
                },
                LightShape::Planar { center, axis_u, axis_v, normal, area, .. } => Entry {
                    kind: Kind::Planar {
                        center: *center,
                        normal: *normal,
                        half_diagonal: (*axis_u + *axis_v).length().max((*axis_u - *axis_v).length()),
                        area: *area,
                    },
                    light: i as u32,
                    power: l.power_estimate(1.0, 0.0),
                },
                // the irradiance (power_estimate's through a sphere of radius 1/√π is E·1)
                LightShape::Distant { .. } => {
                    Entry { kind: Kind::Constant, light: i as u32, power: l.power_estimate(1.0 / PI.sqrt(), 0.0) }
                }
            };
            of_light[i] = (entries.len() as u32, 1.0);
            entries.push(entry);
        }
        for (_, (members, powers)) in groups {
            let dist = Distribution1D::new(&powers);
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            let mut area = 0.0;
            for &li in &members {
                let LightShape::Triangle { prim } = lights[li as usize].shape else { continue };
                for v in tri_positions[prim as usize] {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
                area += areas[prim as usize];
            }
            for (k, &li) in members.iter().enumerate() {
                of_light[li as usize] = (entries.len() as u32, dist.pmf(k));
            }
            let power = dist.total() as f32;
            entries.push(Entry { kind: Kind::Triangles { lo, hi, area, members, dist }, light: u32::MAX, power });
        }
        if world > 0.0 {
            of_light[lights.len()] = (entries.len() as u32, 1.0);
            entries.push(Entry { kind: Kind::Constant, light: lights.len() as u32, power: world });
        }
        let global =
            Distribution1D::new(&entries.iter().map(|e| e.importance(bounds_center, false)).collect::<Vec<_>>());
        // a light that is never chosen (zero power) is dropped from the spatial choice too
        for e in entries.iter_mut() {
            if !(e.power > 0.0) || !e.power.is_finite() {
                e.power = 0.0;
            }
        }
        // one entry (a single light or mesh) or only distance-free ones: the choice is the
        // same everywhere, and the global distribution gives it without per-point work
        let live = entries.iter().filter(|e| e.power > 0.0).count();
        let spatial = (2..=SPATIAL_MAX).contains(&live) && entries.iter().any(|e| !matches!(e.kind, Kind::Constant));
        LightSelector { entries, of_light, global, spatial }
    }

    /// True when there is nothing to sample (no light carries power).
    pub fn is_empty(&self) -> bool {
        self.global.is_empty()
    }

    /// Importances at p (spatial choice), into `w`; their sum.
    #[inline]
    fn importances(&self, p: Vec3, w: &mut [f32; SPATIAL_MAX]) -> f32 {
        let mut sum = 0.0;
        for (wi, e) in w.iter_mut().zip(&self.entries) {
            let v = e.importance(p, true);
            *wi = if v.is_finite() { v } else { 0.0 };
            sum += *wi;
        }
        sum
    }

    /// Chooses a light for shading point p: (light index, probability).
    #[inline]
    pub fn sample(&self, p: Vec3, u: f32) -> Option<(usize, f32)> {
        let (entry, pe, u_rest) = if self.spatial {
            let mut w = [0.0f32; SPATIAL_MAX];
            let sum = self.importances(p, &mut w);
            if !(sum > 0.0) {
                return None;
            }
            // the first entry whose cumulative importance passes u·sum (the last one with
            // weight when rounding leaves u·sum past the end)
            let target = u * sum;
            let (mut acc, mut chosen) = (0.0f32, None);
            for (k, &wk) in w.iter().enumerate().take(self.entries.len()) {
                if wk > 0.0 {
                    chosen = Some((k, acc));
                    if target < acc + wk {
                        break;
                    }
                }
                acc += wk;
            }
            let (k, lo) = chosen?;
            (k, w[k] / sum, ((target - lo) / w[k]).clamp(0.0, 1.0 - f32::EPSILON))
        } else {
            self.global.sample_reuse(u)?
        };
        let e = &self.entries[entry];
        match &e.kind {
            Kind::Triangles { members, dist, .. } => {
                let (m, pm) = dist.sample(u_rest)?;
                Some((members[m] as usize, pe * pm))
            }
            _ => Some((e.light as usize, pe)),
        }
    }

    /// Probability that `sample(p, ·)` chooses light `li` (the world is `lights.len()`).
    #[inline]
    pub fn pmf(&self, li: usize, p: Vec3) -> f32 {
        let Some(&(entry, inner)) = self.of_light.get(li) else { return 0.0 };
        if entry == u32::MAX {
            return 0.0;
        }
        let pe = if self.spatial {
            let mut w = [0.0f32; SPATIAL_MAX];
            let sum = self.importances(p, &mut w);
            if !(sum > 0.0) {
                return 0.0;
            }
            w[entry as usize] / sum
        } else {
            self.global.pmf(entry as usize)
        };
        pe * inner
    }
}

#[cfg(test)]
mod tests {
    use crate::sampler::{IndependentSampler, Sampler};
    use crate::scene::builtin::cornell_mixed_lights;
    use crate::scene::Scene;
    use glam::Vec3;

    /// With every kind of light at once (area, sphere and spot lamps, a sun with an angle,
    /// the world, an emissive mesh): at several shading points the chosen lights' frequencies
    /// match `pmf` (chi-square, 1e-3 level), and each light sample's pdf is what the shift
    /// mapping re-evaluates for that point (`light_eval`: selection × the light's own pdf).
    #[test]
    fn selection_frequencies_match_the_reported_pmf() {
        let scene = Scene::build(&cornell_mixed_lights(8, 8)).unwrap();
        let n_lights = scene.lights.len() + 1;
        let mut s = IndependentSampler::new(17, 0);
        for p in [Vec3::new(0.0, 0.0, -0.99), Vec3::new(-0.9, 0.5, 0.3), Vec3::new(0.5, -0.5, 0.9), Vec3::ZERO] {
            let pmf: Vec<f64> = (0..n_lights).map(|li| scene.selector.pmf(li, p) as f64).collect();
            assert!((pmf.iter().sum::<f64>() - 1.0).abs() < 1e-4, "pmf sums to {}", pmf.iter().sum::<f64>());
            assert!(pmf.iter().filter(|&&q| q > 0.0).count() >= 3, "{pmf:?}");
            let n = 200_000;
            let mut counts = vec![0usize; n_lights];
            let mut silhouette = 0;
            for _ in 0..n {
                let (li, q) = scene.selector.sample(p, s.next_1d()).unwrap();
                assert!((q as f64 - pmf[li]).abs() <= 1e-5 * pmf[li].max(1e-3), "light {li}: {q} vs {}", pmf[li]);
                counts[li] += 1;
                if let Some((li, ls)) = scene.sample_light(p, s.next_1d(), s.next_2d()) {
                    let z = if ls.dist.is_finite() { ls.p } else { ls.wi };
                    // (a point sampled on a sphere's very silhouette may fail the evaluation's
                    // own facing test by rounding: counted, and required to be rare)
                    let Some((_, pdf)) = scene.light_eval(li, p, z) else {
                        silhouette += 1;
                        continue;
                    };
                    assert!((pdf - ls.pdf).abs() <= 2e-3 * ls.pdf, "light {li}: sampled pdf {} vs eval {pdf}", ls.pdf);
                }
            }
            assert!(silhouette < n / 1000, "{silhouette} light samples not lit when evaluated");
            // chi-square over the lights (those with expected counts ≥ 5), df = bins − 1
            let (mut chi2, mut bins) = (0.0, 0);
            for (c, q) in counts.iter().zip(&pmf) {
                let e = q * n as f64;
                if e >= 5.0 {
                    chi2 += (*c as f64 - e).powi(2) / e;
                    bins += 1;
                } else {
                    assert!((*c as f64) < 5.0 + 10.0 * e.max(1.0), "a light of pmf {q} chosen {c} times");
                }
            }
            // 1e-3 critical values of chi-square for df = 1..12
            let crit = [10.83, 13.82, 16.27, 18.47, 20.52, 22.46, 24.32, 26.12, 27.88, 29.59, 31.26, 32.91];
            assert!(chi2 < crit[(bins - 2).min(11)], "p = {p}: chi2 {chi2} over {bins} lights");
        }
    }

    /// A light far away or facing away gets less of the choice than one near the point: the
    /// area light (emitting down from the ceiling) is not chosen from above its plane, and
    /// the spot not outside its cone.
    #[test]
    fn lights_that_cannot_reach_a_point_are_not_chosen_there() {
        let scene = Scene::build(&cornell_mixed_lights(8, 8)).unwrap();
        let area = scene.lights.iter().position(|l| l.name == "Area").unwrap();
        let spot = scene.lights.iter().position(|l| l.name == "Spot").unwrap();
        assert!(scene.selector.pmf(area, Vec3::new(0.0, 0.0, -0.9)) > 0.05);
        assert_eq!(scene.selector.pmf(area, Vec3::new(0.0, 0.0, 0.99)), 0.0); // above its plane
        assert!(scene.selector.pmf(spot, Vec3::new(0.6, 0.0, -0.99)) > 0.0);
        assert_eq!(scene.selector.pmf(spot, Vec3::new(0.6, 0.0, 0.95)), 0.0); // behind the spot
    }

    /// A single area light that faces away from the scene's centre (an uplight under the
    /// ceiling) is still the one light chosen where it shines: the global choice, used for one
    /// light, must not weigh it by its facing at the centre (it did, and NEE never sampled
    /// it: a USD test of a RectLight failed).
    #[test]
    fn a_single_light_facing_away_from_the_centre_is_still_sampled() {
        let mut desc = cornell_mixed_lights(8, 8);
        desc.lights.truncate(1); // the area light
        desc.world = [0.0; 3];
        desc.materials.iter_mut().for_each(|m| m.emission = [0.0; 3]);
        let crate::scene::desc::LightDesc::Area { to_world, .. } = &mut desc.lights[0] else { unreachable!() };
        // emitting up (local −Z turned to +Z) from z = 0.5: the bounds' centre lies behind it
        *to_world = [[1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.5], [0.0, 0.0, 0.0, 1.0]];
        let scene = Scene::build(&desc).unwrap();
        assert!(scene.has_lights());
        let p = Vec3::new(0.1, 0.0, 0.95);
        assert_eq!(scene.selector.pmf(0, p), 1.0);
        let mut s = IndependentSampler::new(1, 1);
        assert!(scene.sample_light(p, s.next_1d(), s.next_2d()).is_some());
    }
}
