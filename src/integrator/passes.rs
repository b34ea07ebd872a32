//! Data passes, as Cycles writes them: Depth (the camera-space z of what a pixel's first
//! camera sample hits; 1e10 where it sees nothing, the value Blender's compositor reads as
//! "far"), Position (its world position; 0 where nothing), Object Index and Material Index (the Pass
//! Index of its object and of its material; 0 where nothing) — from the first sample only,
//! not anti-aliased, as in Cycles. The same for every method: one camera ray per pixel,
//! the ray of pt's sample 0. As Cycles' View Layer › Passes › Alpha Threshold (0.5, its
//! default) does, the ray goes on through surfaces less opaque than `ALPHA_THRESHOLD` — a
//! clear Transparent BSDF, a cut-out's holes, the boundary of a volume — to the first
//! surface at least that opaque.

use super::pt::pixel_sampler;
use crate::accel::TriHit;
use crate::film::Image;
use crate::sampler::Sampler;
use crate::scene::Scene;
use rayon::prelude::*;

/// Depth where a camera ray hits nothing (Blender's value for the background).
pub const NO_DEPTH: f32 = 1e10;

/// Surfaces with an alpha (one minus their pass-through) below this are passed by the data
/// passes' rays: Blender's default Alpha Threshold.
pub const ALPHA_THRESHOLD: f32 = 0.5;

/// Surfaces a data pass ray passes at most before it takes the next one, whatever its alpha.
const MAX_PASSED: usize = 64;

/// What the first camera ray of a pixel sees.
struct FirstHit {
    depth: f32,
    position: [f32; 3],
    object_index: f32,
    material_index: f32,
}

/// The "Depth", "Object Index", "Material Index" (1 channel) and "Position" (RGB = xyz) layers.
pub fn data_passes(scene: &Scene, seed: u64) -> Vec<(String, Image)> {
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let px: Vec<FirstHit> = (0..w * h)
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let mut s = pixel_sampler(seed, i, 0);
            let raster = scene.camera.pixel_raster(x as f32, y as f32, s.next_2d());
            let ray = scene.camera.generate_ray(raster, s.next_2d());
            let mut hit = scene.intersect_camera(ray.origin, ray.dir, ray.tmin, ray.tmax);
            for _ in 0..MAX_PASSED {
                let Some(h) = hit else { break };
                let si = scene.interaction(&h, ray.dir);
                let alpha = 1.0 - scene.bsdf_at(&si).pass_through().element_sum() / 3.0;
                if alpha >= ALPHA_THRESHOLD {
                    break;
                }
                // the rest of the camera ray's segment, from the surface on (t from the camera)
                let tmax = if ray.tmax.is_finite() { (ray.tmax - h.t).max(0.0) } else { f32::INFINITY };
                hit = scene
                    .intersect_camera(si.spawn_origin(ray.dir), ray.dir, 0.0, tmax)
                    .map(|n| TriHit { t: n.t + h.t, ..n });
            }
            match hit {
                Some(hit) => {
                    let p = ray.origin + ray.dir * hit.t;
                    let (ob, ma) = scene.pass_indices(hit.prim);
                    FirstHit {
                        depth: scene.camera.axial_depth(p),
                        position: p.to_array(),
                        object_index: ob as f32,
                        material_index: ma as f32,
                    }
                }
                None => FirstHit { depth: NO_DEPTH, position: [0.0; 3], object_index: 0.0, material_index: 0.0 },
            }
        })
        .collect();
    let value = |f: fn(&FirstHit) -> f32| Image { width: w, height: h, channels: 1, data: px.iter().map(f).collect() };
    let position = Image { width: w, height: h, channels: 3, data: px.iter().flat_map(|p| p.position).collect() };
    vec![
        ("Depth".into(), value(|p| p.depth)),
        ("Position".into(), position),
        ("Object Index".into(), value(|p| p.object_index)),
        ("Material Index".into(), value(|p| p.material_index)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin::cornell_box;

    /// In the Cornell box a pixel that sees the box has its position inside it (|x|, |y|,
    /// |z| ≤ 1) and its depth = its distance along the viewing axis (the camera
    /// looks down +y: depth = y − the camera's y); a pixel that sees past the open front gets
    /// Blender's 1e10 and position 0; without the back wall many more pixels see out.
    #[test]
    fn depth_and_position_of_the_first_camera_ray() {
        let mut desc = cornell_box(16, 16);
        let cam_y = desc.camera.to_world[1][3];
        let scene = Scene::build(&desc).unwrap();
        let layers = data_passes(&scene, 3);
        let (depth, pos) = (&layers[0].1, &layers[1].1);
        let mut seen = 0;
        for i in 0..16 * 16 {
            let p = &pos.data[3 * i..3 * i + 3];
            if depth.data[i] == NO_DEPTH {
                assert_eq!(p, [0.0; 3]);
                continue;
            }
            seen += 1;
            assert!(p.iter().all(|c| c.abs() <= 1.0 + 1e-3), "pixel {i} at {p:?} is outside the box");
            assert!((depth.data[i] - (p[1] - cam_y)).abs() < 1e-3, "depth {} at {p:?}", depth.data[i]);
        }
        assert!(seen > 128, "{seen} pixels see the box"); // 170 of 256: the camera sees past the open front
        desc.meshes.retain(|m| m.name != "BackWall");
        let open = data_passes(&Scene::build(&desc).unwrap(), 3);
        let far = open[0].1.data.iter().filter(|&&d| d == NO_DEPTH).count();
        assert!(far > 256 - seen + 10, "{far} pixels see out");
    }

    /// Through surfaces less opaque than the Alpha Threshold, as Cycles: a clear sheet across
    /// the whole view (a Transparent BSDF, or a volume's boundary) leaves every pass as it is
    /// without it; at alpha 0.7 the sheet is what the passes see. (The passes saw the sheet
    /// at any alpha, and this test failed.)
    #[test]
    fn data_passes_look_through_surfaces_below_the_alpha_threshold() {
        use crate::scene::desc::{MaterialDesc, MeshDesc};
        let plain = cornell_box(16, 16);
        let cam_y = plain.camera.to_world[1][3];
        let with_sheet = |transparency: f32| {
            let mut d = plain.clone();
            d.materials.push(MaterialDesc { name: "Sheet".into(), transparency, ..Default::default() });
            let (y, m) = (cam_y + 0.5, d.materials.len() as u32 - 1);
            d.meshes.push(MeshDesc {
                name: "Sheet".into(),
                positions: vec![[-9.0, y, -9.0], [9.0, y, -9.0], [9.0, y, 9.0], [-9.0, y, 9.0]],
                indices: vec![[0, 1, 2], [0, 2, 3]],
                material_ids: vec![m, m],
                ..Default::default()
            });
            data_passes(&Scene::build(&d).unwrap(), 3)
        };
        let base = data_passes(&Scene::build(&plain).unwrap(), 3);
        let clear = with_sheet(1.0);
        for ((name, a), (_, b)) in base.iter().zip(&clear) {
            let worst = a.data.iter().zip(&b.data).map(|(x, y)| (x - y).abs() / x.abs().max(1.0)).fold(0.0, f32::max);
            assert!(worst < 1e-3, "{name}: the clear sheet changed it by {worst}");
            // (the ray goes on from an offset origin)
        }
        let seen = with_sheet(0.3);
        assert!(seen[0].1.data.iter().all(|&d| (d - 0.5).abs() < 1e-3), "depth {:?}", &seen[0].1.data[..4]);
    }

    /// Object Index and Material Index carry the Pass Index of the object and material the first camera
    /// ray hits: the left wall (object 7, material Red = 3) where the position is on it, the
    /// right wall (object 0: its own index; material Green = 5), 0 where nothing is hit.
    #[test]
    fn object_and_material_index_of_the_first_camera_ray() {
        let mut desc = cornell_box(24, 24);
        desc.meshes.iter_mut().find(|m| m.name == "LeftWall").unwrap().pass_index = 7;
        desc.materials[1].pass_index = 3; // Red: the left wall
        desc.materials[2].pass_index = 5; // Green: the right wall
        let layers = data_passes(&Scene::build(&desc).unwrap(), 1);
        let get = |name: &str| &layers.iter().find(|(n, _)| n == name).unwrap().1;
        let (depth, pos, ob, ma) = (get("Depth"), get("Position"), get("Object Index"), get("Material Index"));
        let (mut left, mut right) = (0, 0);
        for i in 0..24 * 24 {
            let x = pos.data[3 * i];
            let expect = if depth.data[i] == NO_DEPTH {
                (0.0, 0.0)
            } else if (x + 1.0).abs() < 1e-4 {
                left += 1;
                (7.0, 3.0)
            } else if (x - 1.0).abs() < 1e-4 {
                right += 1;
                (0.0, 5.0)
            } else {
                (0.0, 0.0) // white surfaces (the light's material has index 0 too)
            };
            assert_eq!((ob.data[i], ma.data[i]), expect, "pixel {i} at x = {x}");
        }
        assert!(left > 20 && right > 20, "{left} and {right} pixels see the side walls");
    }
}
