//! The blend of two Principled mixtures by a factor f ∈ (0, 1): what a Mix Shader whose
//! factor is a texture renders at one point, (1 − f)·A + f·B.
//!
//! Both sides are mixtures of the same lobes (layered diffuse, metal, glass, diffuse
//! transmission, pass-through) with weights w; the blend is the one mixture whose weights
//! are (1 − f)·w_A + f·w_B and whose lobes take each side's parameters averaged by that
//! side's share of the lobe's weight. Colours enter a lobe linearly (the metal's through
//! Schlick's affine F0 term), so where the two sides' lobes differ only in colour — two
//! Principled BSDFs of different base colour, metallic, transmission or alpha, the common
//! mask-driven mix — the blend is exact; roughness, IORs, the specular layer's coverage
//! under different base colours and the coat are averaged, as the exporter averages them
//! for a Mix Shader of constant factor.

use super::{Bsdf, Coat, Conductor, Dielectric, Lambert, Layered, Translucent};

/// The weighted mean of two values with weights `wa`, `wb` (`a` when both are 0).
#[inline]
fn mean<T>(a: T, wa: f32, b: T, wb: f32) -> T
where
    T: std::ops::Mul<f32, Output = T> + std::ops::Add<Output = T> + Copy,
{
    let w = wa + wb;
    if w > 0.0 {
        a * (wa / w) + b * (wb / w)
    } else {
        a
    }
}

impl Bsdf {
    /// (1 − f)·a + f·b for two `Bsdf::Principled` mixtures (`Material::lobes` with
    /// `general`); another variant on either side is taken whole by the nearer end of f.
    pub fn blend(a: &Bsdf, b: &Bsdf, f: f32) -> Bsdf {
        let (
            Bsdf::Principled {
                diffuse: da,
                metal: ma,
                glass: ga,
                w: wa,
                pass: pa,
                pass_tint: ta,
                coat: ca,
                translucent: la,
            },
            Bsdf::Principled {
                diffuse: db,
                metal: mb,
                glass: gb,
                w: wb,
                pass: pb,
                pass_tint: tb,
                coat: cb,
                translucent: lb,
            },
        ) = (a, b)
        else {
            return if f < 0.5 { *a } else { *b };
        };
        let g = 1.0 - f;
        // each side's weight of each lobe
        let (d1, d2) = (g * wa[0], f * wb[0]);
        let (m1, m2) = (g * wa[1], f * wb[1]);
        let (t1, t2) = (g * wa[2], f * wb[2]);
        let (s1, s2) = (d1 * da.coverage, d2 * db.coverage); // the specular layers'
        let diffuse = Layered {
            base: Lambert {
                albedo: mean(da.base.albedo, d1, db.base.albedo, d2),
                roughness: mean(da.base.roughness, d1, db.base.roughness, d2),
                power: da.base.power,
                unmapped: da.base.unmapped,
            },
            eta: mean(da.eta, s1, db.eta, s2),
            roughness: mean(da.roughness, s1, db.roughness, s2),
            coverage: if d1 + d2 > 0.0 { (s1 + s2) / (d1 + d2) } else { 0.0 },
            tint: mean(da.tint, s1, db.tint, s2),
            // (the walk takes the parameters of the side that has one, the heavier if both)
            subsurface: if d1 + d2 > 0.0 { (d1 * da.subsurface + d2 * db.subsurface) / (d1 + d2) } else { 0.0 },
            subsurface_ior: if d1 * da.subsurface >= d2 * db.subsurface {
                da.subsurface_ior
            } else {
                db.subsurface_ior
            },
        };
        let heavier = |x: bool, y: bool, wx: f32, wy: f32| if wx >= wy { x } else { y };
        let metal = Conductor {
            f0: mean(ma.f0, m1, mb.f0, m2),
            roughness: mean(ma.roughness, m1, mb.roughness, m2),
            multiscatter: heavier(ma.multiscatter, mb.multiscatter, m1, m2),
            f82: mean(ma.f82, m1, mb.f82, m2),
            constant: heavier(ma.constant, mb.constant, m1, m2),
        };
        let glass = Dielectric {
            eta: mean(ga.eta, t1, gb.eta, t2),
            tint: mean(ga.tint, t1, gb.tint, t2),
            reflection_tint: mean(ga.reflection_tint, t1, gb.reflection_tint, t2),
            roughness: mean(ga.roughness, t1, gb.roughness, t2),
            multiscatter: heavier(ga.multiscatter, gb.multiscatter, t1, t2),
        };
        let (p1, p2) = (g * pa, f * pb);
        let (c1, c2) = (g * ca.weight, f * cb.weight);
        let coat = Coat {
            weight: c1 + c2,
            eta: mean(ca.eta, c1, cb.eta, c2),
            roughness: mean(ca.roughness, c1, cb.roughness, c2),
            tint: mean(ca.tint, c1, cb.tint, c2),
        };
        let (l1, l2) = (g * la.weight, f * lb.weight);
        let translucent =
            Translucent { weight: l1 + l2, albedo: mean(la.albedo, l1, lb.albedo, l2), unmapped: la.unmapped };
        Bsdf::Principled {
            diffuse,
            metal,
            glass,
            w: [d1 + d2, m1 + m2, t1 + t2],
            pass: p1 + p2,
            pass_tint: mean(*ta, p1, *tb, p2),
            coat,
            translucent,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Spectrum;
    use glam::{Vec2, Vec3};

    fn principled(base: Spectrum, metallic: f32, transmission: f32, pass: f32) -> Bsdf {
        let rest = 1.0 - pass;
        Bsdf::Principled {
            diffuse: Layered {
                base: Lambert::new(base),
                eta: 1.5,
                roughness: 0.4,
                coverage: 1.0,
                tint: Spectrum::ONE,
                subsurface: 0.0,
                subsurface_ior: 0.0,
            },
            metal: Conductor { f0: base, roughness: 0.4, multiscatter: true, f82: Spectrum::ONE, constant: false },
            glass: Dielectric {
                eta: 1.5,
                tint: base,
                reflection_tint: Spectrum::ONE,
                roughness: 0.4,
                multiscatter: true,
            },
            w: [
                (1.0 - metallic) * (1.0 - transmission) * rest,
                metallic * rest,
                (1.0 - metallic) * transmission * rest,
            ],
            pass,
            pass_tint: Spectrum::ONE,
            coat: Coat::NONE,
            translucent: Translucent::NONE,
        }
    }

    /// Where the two sides differ only in colour, metallic, transmission and pass-through
    /// (the lobes' colours enter linearly), the blend's value and pdf are exactly
    /// (1 − f)·A + f·B in every direction, and its importance sampling returns weights
    /// f·cos / pdf of its own value and pdf.
    #[test]
    fn blend_of_principled_mixtures_is_their_linear_mix() {
        let a = principled(Vec3::new(0.9, 0.6, 0.1), 1.0, 0.0, 0.0); // gold
        let b = principled(Vec3::new(0.2, 0.5, 0.8), 0.0, 0.3, 0.4); // paint, some glass, cut out
        let dirs = [
            Vec3::new(0.3, 0.2, 0.93).normalize(),
            Vec3::new(-0.6, 0.1, 0.79).normalize(),
            Vec3::new(0.1, -0.5, -0.86).normalize(),
            Vec3::new(0.7, 0.0, 0.71).normalize(),
        ];
        for f in [0.1f32, 0.5, 0.85] {
            let m = Bsdf::blend(&a, &b, f);
            for wo in dirs.iter().filter(|d| d.z > 0.0) {
                for wi in dirs {
                    let want = a.eval(*wo, wi) * (1.0 - f) + b.eval(*wo, wi) * f;
                    let got = m.eval(*wo, wi);
                    assert!((got - want).abs().max_element() <= 1e-5 * (1.0 + want.max_element()), "{got} {want}");
                }
                let through = m.pass_through();
                let want = a.pass_through() * (1.0 - f) + b.pass_through() * f;
                assert!((through - want).abs().max_element() < 1e-6);
                for k in 0..64 {
                    let u = Vec2::new((k as f32 + 0.5) / 64.0, ((k * 37 % 64) as f32 + 0.5) / 64.0);
                    let Some(s) = m.sample(*wo, ((k * 11 % 64) as f32 + 0.5) / 64.0, u) else { continue };
                    if s.lobe == crate::bsdf::LobeKind::Specular {
                        continue;
                    }
                    let want = m.eval(*wo, s.wi) / m.pdf(*wo, s.wi);
                    assert!((s.weight - want).abs().max_element() < 1e-3 * (1.0 + want.max_element()));
                }
            }
        }
    }

    /// The blend's ends are its sides.
    #[test]
    fn blend_ends_are_the_sides() {
        let a = principled(Vec3::new(0.9, 0.6, 0.1), 0.5, 0.0, 0.0);
        let b = principled(Vec3::new(0.2, 0.5, 0.8), 0.0, 0.0, 0.5);
        let (wo, wi) = (Vec3::new(0.3, 0.2, 0.93).normalize(), Vec3::new(-0.6, 0.1, 0.79).normalize());
        for (f, side) in [(1e-7f32, &a), (1.0 - 1e-7, &b)] {
            let got = Bsdf::blend(&a, &b, f).eval(wo, wi);
            assert!((got - side.eval(wo, wi)).abs().max_element() < 1e-5);
        }
    }
}
