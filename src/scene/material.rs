//! Materials: the parameters of the Principled-like uber-material, turned into a BSDF at a
//! surface point. For now the BSDF is the diffuse part (Lambert with the base colour);
//! metallic, transmission and roughness are stored and validated for the specular BSDFs.

use super::desc::MaterialDesc;
use crate::bsdf::{Bsdf, Lambert};
use crate::error::SceneError;
use crate::math::Spectrum;
use glam::Vec3;

#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub base_color: Spectrum,
    pub emission: Spectrum,
    pub roughness: f32,
    pub metallic: f32,
    pub transmission: f32,
    pub ior: f32,
}

impl Material {
    pub fn from_desc(d: &MaterialDesc) -> Result<Material, SceneError> {
        let bad = |what: &str| SceneError::Material { material: d.name.clone(), what: what.to_string() };
        let scalars = [d.roughness, d.metallic, d.transmission, d.ior];
        if d.base_color.iter().chain(d.emission.iter()).chain(scalars.iter()).any(|x| !x.is_finite()) {
            return Err(bad("NaN or Inf parameter"));
        }
        if d.emission.iter().any(|&x| x < 0.0) {
            return Err(bad("negative emission"));
        }
        Ok(Material {
            name: d.name.clone(),
            // Albedo above 1 would add energy; Cycles clamps the base colour the same way.
            base_color: Vec3::from_array(d.base_color).clamp(Vec3::ZERO, Vec3::ONE),
            emission: Vec3::from_array(d.emission),
            roughness: d.roughness.clamp(0.0, 1.0),
            metallic: d.metallic.clamp(0.0, 1.0),
            transmission: d.transmission.clamp(0.0, 1.0),
            ior: if d.ior > 0.0 { d.ior } else { 1.0 },
        })
    }

    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// The BSDF at a surface point.
    #[inline]
    pub fn bsdf(&self) -> Bsdf {
        // Diffuse part of the Principled BSDF: a metal or a fully transmissive surface has none.
        let diffuse = self.base_color * (1.0 - self.metallic) * (1.0 - self.transmission);
        Bsdf::Lambert(Lambert { albedo: diffuse })
    }
}
