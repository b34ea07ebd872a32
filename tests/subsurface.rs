//! Subsurface scattering (src/medium/subsurface.rs) under every method: a waxy block (Random
//! Walk, anisotropic) and a skin block (Random Walk (Skin)) under a lamp and a dim world
//! render the image `pt` renders, channel by channel, with every method, NEE and naive —
//! `bdpt`'s camera subpaths walking and its MIS leaving out the strategies a light subpath
//! would have to walk for, the gradient-domain shift leaving walked paths to the base.

use gdmlt::integrator::{render, Method, RenderControl, RenderSettings};
use gdmlt::path::PathSettings;
use gdmlt::scene::builtin::{camera_looking_along_y, closed_box};
use gdmlt::scene::desc::SubsurfaceDesc;
use gdmlt::scene::{MaterialDesc, Scene, SceneDesc};

fn subsurface(name: &str, colour: [f32; 3], radius: [f32; 3], anisotropy: f32, method: &str) -> MaterialDesc {
    MaterialDesc {
        name: name.into(),
        base_color: colour,
        roughness: 0.3,
        specular_ior: 1.5,
        specular: 1.0,
        subsurface: Some(SubsurfaceDesc { weight: 1.0, radius, anisotropy, ior: 1.4, method: method.into() }),
        ..Default::default()
    }
}

fn scene() -> SceneDesc {
    let lamp = MaterialDesc { name: "Lamp".into(), base_color: [0.0; 3], emission: [30.0; 3], ..Default::default() };
    SceneDesc {
        meshes: vec![
            closed_box("Wax", [-0.6, 2.5, -0.5], [0.0, 3.5, 0.5], 0),
            closed_box("Skin", [0.05, 2.6, -0.4], [0.6, 3.2, 0.3], 1),
            closed_box("Lamp", [-1.2, 2.2, 1.5], [-0.6, 3.2, 1.7], 2),
        ],
        materials: vec![
            subsurface("Wax", [0.9, 0.6, 0.3], [1.0, 0.4, 0.2], 0.5, "random_walk"),
            subsurface("Skin", [0.8, 0.5, 0.4], [0.5, 0.2, 0.1], 0.0, "skin"),
            lamp,
        ],
        camera: camera_looking_along_y([0.0, 0.0, 0.0], 60.0, 12, 12),
        world: [0.02; 3],
        ..Default::default()
    }
}

/// Per-channel image mean of two renders (seeds `seed`, `seed + 1`) and its standard error
/// from their pixels' differences (the noise alone, not the image's structure).
fn mean_and_error(scene: &Scene, method: Method, nee: bool, spp: u32, seed: u64) -> ([f64; 3], [f64; 3]) {
    let image = |seed: u64| {
        let path = PathSettings::new(6, nee);
        let settings = RenderSettings { method, spp, seed, path, threads: 2, ..Default::default() };
        let out = render(scene, &settings, &RenderControl::new(0.0)).unwrap();
        let img = out.layer("Combined").unwrap();
        (0..img.width * img.height)
            .map(|i| [0, 1, 2].map(|c| img.data[i * img.channels + c] as f64))
            .collect::<Vec<_>>()
    };
    let (a, b) = (image(seed), image(seed + 1));
    let n = a.len() as f64;
    let (mut m, mut e) = ([0.0; 3], [0.0; 3]);
    for c in 0..3 {
        m[c] = a.iter().zip(&b).map(|(x, y)| x[c] + y[c]).sum::<f64>() / (2.0 * n);
        e[c] = (a.iter().zip(&b).map(|(x, y)| (x[c] - y[c]).powi(2)).sum::<f64>() / (4.0 * n * n)).sqrt();
    }
    (m, e)
}

/// Tolerance: 5 standard errors of both means (from their seeds' differences) and,
/// for the Metropolis methods, 2% for their normalisation's own noise.
#[test]
fn every_method_walks_beneath_the_surface_as_pt_does() {
    let scene = Scene::build(&scene()).unwrap();
    let (want, want_e) = mean_and_error(&scene, Method::Pt, true, 4096, 11);
    assert!(want.iter().all(|&x| x > 0.05), "{want:?}");
    for (method, nee) in [
        (Method::Pt, false),
        (Method::Bdpt, true),
        (Method::Gdpt, true),
        (Method::Pssmlt, true),
        (Method::Gdpssmlt, true),
        (Method::Gdpssmlt, false),
    ] {
        let (m, e) = mean_and_error(&scene, method, nee, if nee { 256 } else { 8192 }, 7);
        let slack = if matches!(method, Method::Pssmlt | Method::Gdpssmlt) { 0.02 } else { 0.0 };
        for c in 0..3 {
            let tol = 5.0 * (e[c] * e[c] + want_e[c] * want_e[c]).sqrt() + slack * want[c];
            assert!(
                (m[c] - want[c]).abs() < tol,
                "{method:?} nee={nee}: channel {c} {:.4} against pt's {:.4} (±{tol:.4})",
                m[c],
                want[c]
            );
        }
    }
}

/// Without the walk (the subsurface weight 0: the diffuse base) the image differs beyond the
/// tolerance above: the test sees the walk.
#[test]
fn the_walk_changes_the_image() {
    let with = Scene::build(&scene()).unwrap();
    let mut plain = scene();
    for m in &mut plain.materials {
        m.subsurface = None;
    }
    let plain = Scene::build(&plain).unwrap();
    let (a, ea) = mean_and_error(&with, Method::Pt, true, 256, 1);
    let (b, eb) = mean_and_error(&plain, Method::Pt, true, 256, 3);
    let far = (0..3).any(|c| (a[c] - b[c]).abs() > 5.0 * (ea[c] * ea[c] + eb[c] * eb[c]).sqrt());
    assert!(far, "{a:?} vs {b:?}");
}
