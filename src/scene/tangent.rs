//! MikkTSpace tangents (Mikkelsen 2008), the tangent frame Blender bakes normal maps in and
//! Cycles renders them with: per triangle corner, a unit tangent along ∂p/∂u, welded and
//! averaged over the corners that share a position, normal and UV, and the sign of the
//! bitangent (B = sign · N × T). Cycles runs MikkTSpace on the triangulated mesh with its
//! corner normals (smooth or flat) and the render UV map; so does `corner_tangents`, on the
//! world-space mesh the exporter hands over (the same frame under rotation, translation and
//! uniform scale).

use super::desc::MeshDesc;
use bevy_mikktspace::{generate_tangents, Geometry};
use glam::Vec3;

/// The mesh's corners as MikkTSpace reads them, and the tangents it writes back.
struct Corners<'a> {
    mesh: &'a MeshDesc,
    /// Per corner: tangent xyz and bitangent sign; zero where MikkTSpace gave none (a
    /// degenerate face without neighbours).
    out: Vec<[f32; 4]>,
}

impl Geometry for Corners<'_> {
    fn num_faces(&self) -> usize {
        self.mesh.indices.len()
    }

    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }

    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.mesh.positions[self.mesh.indices[face][vert] as usize]
    }

    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        // (a broken corner normal renders flat, as the scene's triangles do)
        if let Some(n) = self.mesh.corner_normals.get(3 * face + vert) {
            let v = Vec3::from_array(*n);
            if v.is_finite() && v.length_squared() > 1e-12 {
                return v.normalize().to_array();
            }
        }
        let p = self.mesh.indices[face].map(|i| Vec3::from_array(self.mesh.positions[i as usize]));
        (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero().to_array()
    }

    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        self.mesh.corner_uvs[3 * face + vert]
    }

    fn set_tangent(&mut self, tangent_space: Option<bevy_mikktspace::TangentSpace>, face: usize, vert: usize) {
        self.out[3 * face + vert] = tangent_space.map_or([0.0; 4], |t| t.tangent_encoded());
    }
}

/// The MikkTSpace tangent of every corner of `mesh` (3 per triangle, in triangle order;
/// xyz and the bitangent sign ±1; zero where none exists). The mesh must have UVs.
pub fn corner_tangents(mesh: &MeshDesc) -> Vec<[f32; 4]> {
    debug_assert_eq!(mesh.corner_uvs.len(), 3 * mesh.indices.len());
    let mut corners = Corners { mesh, out: vec![[0.0; 4]; 3 * mesh.indices.len()] };
    if generate_tangents(&mut corners).is_err() {
        // (no error case exists today; zero tangents fall back to each triangle's own frame)
        corners.out.fill([0.0; 4]);
    }
    corners.out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a flat quad whose UVs are turned and scaled, the tangent is ∂p/∂u normalized and
    /// the sign says whether (u, v) turn as the face does; mirroring the UVs flips it.
    #[test]
    fn a_flat_quad_gets_its_uv_gradient_as_tangent() {
        let (c, s) = (0.6f32, 0.8f32); // u along (c, s), v along (−s, c) in the plane, scaled 2×
        let positions = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let uv = |p: [f32; 3], mirror: f32| [2.0 * (c * p[0] + s * p[1]), mirror * 2.0 * (-s * p[0] + c * p[1])];
        for mirror in [1.0, -1.0] {
            let indices = vec![[0, 1, 2], [0, 2, 3]];
            let corner_uvs = indices.iter().flatten().map(|&i: &u32| uv(positions[i as usize], mirror)).collect();
            let mesh =
                MeshDesc { name: "q".into(), positions: positions.clone(), indices, corner_uvs, ..Default::default() };
            for t in corner_tangents(&mesh) {
                let tangent = Vec3::new(t[0], t[1], t[2]);
                assert!((tangent - Vec3::new(c, s, 0.0)).length() < 1e-5, "{tangent}");
                assert_eq!(t[3], mirror, "sign");
            }
        }
    }
}
