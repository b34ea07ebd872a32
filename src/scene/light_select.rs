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
//! ground plane). With more than `SPATIAL_MAX` entries the local ones (all but the sun and the
//! world) go into a light tree (light_tree.rs): the point descends it in O(log N), and the
//! tree's root competes with the distance-free entries by its own importance at the point.
//! With a single entry the choice is the same everywhere (one global distribution).
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
use super::light_tree::{Bounds, Cone, LightTree};
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
                let att = if oriented { spot.map_or(1.0, |s| s.bound(*center, *r2, p)) } else { 1.0 };
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

impl Entry {
    /// The light tree's bounds of a local entry, with its power scaled so that the tree's
    /// importance Φ'·cos/d² is this entry's irradiance estimate (as `importance` above).
    fn bounds(&self) -> Bounds {
        match &self.kind {
            Kind::Sphere { center, r2, spot } => {
                let r = r2.sqrt();
                let cone = match spot {
                    Some(s) => Cone { axis: s.dir, theta_o: s.theta_o, theta_e: 1e-3 },
                    None => Cone::SPHERE,
                };
                Bounds { lo: *center - r, hi: *center + r, power: self.power / (4.0 * PI), cone }
            }
            Kind::Planar { center, normal, half_diagonal, .. } => Bounds {
                lo: *center - Vec3::splat(*half_diagonal),
                hi: *center + Vec3::splat(*half_diagonal),
                power: self.power / PI,
                cone: Cone { axis: *normal, theta_o: 0.0, theta_e: PI / 2.0 },
            },
            Kind::Triangles { lo, hi, .. } => {
                Bounds { lo: *lo, hi: *hi, power: self.power / (2.0 * PI), cone: Cone::SPHERE }
            }
            Kind::Constant => Bounds { lo: Vec3::ZERO, hi: Vec3::ZERO, power: 0.0, cone: Cone::SPHERE },
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
    /// Above `SPATIAL_MAX` entries: the tree over the local entries, and the distance-free ones.
    tree: Option<LightTree>,
    constants: Vec<u32>,
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
                LightShape::Triangle { prim, .. } => {
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
                let LightShape::Triangle { prim, .. } = lights[li as usize].shape else { continue };
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
        let local = entries.iter().any(|e| !matches!(e.kind, Kind::Constant));
        let spatial = (2..=SPATIAL_MAX).contains(&live) && local;
        let (mut tree, mut constants) = (None, Vec::new());
        if live > SPATIAL_MAX && local {
            let items: Vec<(u32, Bounds)> = entries
                .iter()
                .enumerate()
                .filter(|(_, e)| e.power > 0.0 && !matches!(e.kind, Kind::Constant))
                .map(|(i, e)| (i as u32, e.bounds()))
                .collect();
            tree = LightTree::new(&items, entries.len());
            constants = (0..entries.len() as u32)
                .filter(|&i| matches!(entries[i as usize].kind, Kind::Constant) && entries[i as usize].power > 0.0)
                .collect();
        }
        LightSelector { entries, of_light, global, spatial, tree, constants }
    }

    /// The tree's and the distance-free entries' weights at p: (tree, their sum with it).
    #[inline]
    fn top_level(&self, tree: &LightTree, p: Vec3) -> (f32, f32) {
        let t = tree.root_importance(p);
        let t = if t.is_finite() { t } else { 0.0 };
        (t, t + self.constants.iter().map(|&c| self.entries[c as usize].power).sum::<f32>())
    }

    /// Tree mode: (entry, its probability, the rest of u).
    fn sample_tree(&self, tree: &LightTree, p: Vec3, u: f32) -> Option<(usize, f32, f32)> {
        let (t, sum) = self.top_level(tree, p);
        if !(sum > 0.0) {
            return None;
        }
        let target = u * sum;
        if target < t {
            let (entry, q, rest) = tree.sample(p, (target / t).min(1.0 - f32::EPSILON))?;
            return Some((entry as usize, q * t / sum, rest));
        }
        let mut acc = t;
        let mut last = None;
        for &c in &self.constants {
            let w = self.entries[c as usize].power;
            last = Some((c as usize, w / sum, ((target - acc) / w).clamp(0.0, 1.0 - f32::EPSILON)));
            if target < acc + w {
                break;
            }
            acc += w;
        }
        last
    }

    /// Tree mode: the probability of choosing `entry` at p.
    fn pmf_tree(&self, tree: &LightTree, entry: u32, p: Vec3) -> f32 {
        let (t, sum) = self.top_level(tree, p);
        if !(sum > 0.0) {
            return 0.0;
        }
        if matches!(self.entries[entry as usize].kind, Kind::Constant) {
            return self.entries[entry as usize].power / sum;
        }
        tree.pmf(entry, p) * t / sum
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
        let (entry, pe, u_rest) = if let Some(tree) = &self.tree {
            self.sample_tree(tree, p, u)?
        } else if self.spatial {
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
        let pe = if let Some(tree) = &self.tree {
            self.pmf_tree(tree, entry, p)
        } else if self.spatial {
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

    /// Above `SPATIAL_MAX` entries (the mixed-lights box plus 100 small lamps of varied power
    /// and two spots): the tree's choice reports exactly the pmf it samples, the pmf sums to
    /// 1 over every light (sun and world included) and the frequencies match it.
    #[test]
    fn many_lights_choose_through_the_tree_with_the_pmf_they_report() {
        let mut desc = cornell_mixed_lights(8, 8);
        let mut s = IndependentSampler::new(23, 0);
        for i in 0..100 {
            let position = [s.next_1d() * 1.8 - 0.9, s.next_1d() * 1.8 - 0.9, 0.7 + 0.25 * s.next_1d()];
            let p = 0.2 + 5.0 * s.next_1d();
            let (name, power) = (format!("Lamp{i}"), [p, p * s.next_1d(), p]);
            desc.lights.push(if i % 50 == 0 {
                crate::scene::desc::LightDesc::Spot {
                    name,
                    position,
                    direction: [0.0, 0.0, -1.0],
                    radius: 0.02,
                    power,
                    spot_size: 0.8,
                    spot_blend: 0.2,
                    soft_falloff: true,
                    visible_camera: false,
                    cast_shadow: true,
                    matrix: None,
                }
            } else {
                crate::scene::desc::LightDesc::Point {
                    name,
                    position,
                    radius: 0.01,
                    power,
                    soft_falloff: true,
                    visible_camera: false,
                    cast_shadow: true,
                }
            });
        }
        let scene = Scene::build(&desc).unwrap();
        assert!(scene.selector.tree.is_some());
        let n_lights = scene.lights.len() + 1;
        for p in [Vec3::new(0.0, 0.0, 0.99), Vec3::new(-0.9, 0.5, 0.3), Vec3::new(0.2, -0.3, -0.99)] {
            let mut pmf: Vec<f64> = (0..n_lights).map(|li| scene.selector.pmf(li, p) as f64).collect();
            let total = pmf.iter().sum::<f64>();
            assert!(total <= 1.0 + 1e-4 && total > 0.5, "pmf sums to {total}");
            pmf.push(1.0 - total); // "no light" (see light_tree.rs's test)
            let n = 300_000;
            let mut counts = vec![0usize; n_lights + 1];
            for _ in 0..n {
                let Some((li, q)) = scene.selector.sample(p, s.next_1d()) else {
                    counts[n_lights] += 1;
                    continue;
                };
                assert!((q as f64 - pmf[li]).abs() <= 1e-4 * pmf[li].max(1e-4), "light {li}: {q} vs {}", pmf[li]);
                counts[li] += 1;
            }
            let (chi2, df) = crate::test_stats::chi_square(&counts, &pmf, n);
            let crit = crate::test_stats::critical_1e3(df);
            assert!(chi2 < crit, "p = {p}: chi2 {chi2} at {df} degrees of freedom (critical {crit})");
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
