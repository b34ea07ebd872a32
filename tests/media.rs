//! Participating media (src/medium) under every method, against closed forms: a scattering
//! medium in a white furnace stays white (every channel, every method, NEE and naive), and an
//! absorbing slab transmits exp(−σa·d) of the light behind it.

use gdmlt::integrator::{render, Method, RenderControl, RenderSettings};
use gdmlt::path::PathSettings;
use gdmlt::scene::builtin::{camera_looking_along_y, closed_box};
use gdmlt::scene::desc::VolumeDesc;
use gdmlt::scene::{MaterialDesc, MeshDesc, Scene, SceneDesc};

/// A boundary-only material (a Volume output without Surface) holding `volume`.
fn medium(name: &str, volume: VolumeDesc) -> MaterialDesc {
    MaterialDesc {
        name: name.into(),
        base_color: [0.0; 3],
        transparency: 1.0,
        transparent_color: [1.0; 3],
        volume: Some(volume),
        ..Default::default()
    }
}

/// A purely absorbing homogeneous medium of coefficients `sigma`.
fn absorber(sigma: [f32; 3]) -> VolumeDesc {
    VolumeDesc { absorption: sigma, ..Default::default() }
}

fn scene(meshes: Vec<MeshDesc>, materials: Vec<MaterialDesc>, world: [f32; 3], size: u32) -> SceneDesc {
    SceneDesc {
        meshes,
        materials,
        camera: camera_looking_along_y([0.0, 0.0, 0.0], 25.0, size, size),
        world,
        ..Default::default()
    }
}

/// Per-channel mean over the image and its standard error from the pixels' spread.
fn mean_and_error(desc: &SceneDesc, method: Method, nee: bool, spp: u32, seed: u64) -> ([f64; 3], [f64; 3]) {
    let scene = Scene::build(desc).unwrap();
    let path = PathSettings { volume_bounces: 1024, ..PathSettings::new(1024, nee) };
    let settings = RenderSettings { method, spp, seed, path, threads: 2, ..Default::default() };
    let out = render(&scene, &settings, &RenderControl::new(0.0)).unwrap();
    let img = out.layer("Combined").unwrap();
    let n = (img.width * img.height) as f64;
    let (mut m, mut e) = ([0.0; 3], [0.0; 3]);
    for c in 0..3 {
        let v: Vec<f64> = (0..img.width * img.height).map(|i| img.data[i * img.channels + c] as f64).collect();
        m[c] = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - m[c]).powi(2)).sum::<f64>() / (n - 1.0);
        e[c] = (var / n).sqrt();
    }
    (m, e)
}

const METHODS: [(Method, bool); 7] = [
    (Method::Pt, true),
    (Method::Pt, false),
    (Method::Gdpt, true),
    (Method::Pssmlt, true),
    (Method::Gdpssmlt, true),
    (Method::Gdpssmlt, false),
    (Method::Bdpt, true),
];

/// Radiance is 1 everywhere inside a lossless medium under a world of radiance 1 (no
/// absorption, any scattering, any phase function — Henyey–Greenstein and Mie here): the white
/// furnace of volume rendering.
/// A chromatic scattering coefficient exercises the free flight's spectral MIS; forward
/// scattering the phase function's sampling. Every method, NEE and naive, no bounce limit.
/// Tolerance: 5 standard errors of the image mean (from the pixels' spread) and, for the
/// Metropolis methods, 2% for their normalisation's own noise.
#[test]
fn a_lossless_medium_in_a_white_furnace_stays_white() {
    let fog = medium(
        "Fog",
        VolumeDesc {
            scattering: [0.9, 0.3, 2.5],
            absorption: [0.0; 3],
            emission: [0.0; 3],
            anisotropy: 0.6,
            density: None,
            ..Default::default()
        },
    );
    let mut desc = scene(vec![closed_box("Fog", [-2.0; 3], [2.0; 3], 0)], vec![fog], [1.0; 3], 16);
    assert!(Scene::build(&desc).unwrap().has_media());
    // Henyey–Greenstein, then Mie (sampled from its two lobes, weighted p/pdf)
    for phase in ["hg", "mie"] {
        let v = desc.materials[0].volume.as_mut().unwrap();
        (v.phase, v.diameter) = (phase.into(), 8.0);
        for (method, nee) in METHODS {
            let (m, e) = mean_and_error(&desc, method, nee, 64, 3);
            let slack = if matches!(method, Method::Pssmlt | Method::Gdpssmlt) { 0.02 } else { 0.0 };
            for c in 0..3 {
                assert!(
                    (m[c] - 1.0).abs() < 5.0 * e[c] + slack + 1e-3,
                    "{phase}: {method:?} nee={nee}: channel {c} {:.4} ± {:.4}",
                    m[c],
                    e[c]
                );
            }
        }
    }
}

/// An absorbing slab of depth d between an orthographic camera (rays along its depth) and an
/// emitting wall of radiance 1: every pixel sees exp(−σa·d) per channel (σs = 0: scattered
/// light would add to the uncollided). And the camera inside a medium: the slab grown around
/// it, its rays cross the 2.5 from the camera's plane to the slab's far side.
#[test]
fn an_absorbing_slab_transmits_exp_minus_sigma_d() {
    let sigma = [0.5f32, 1.0, 2.0];
    let wall = MaterialDesc { name: "Wall".into(), base_color: [0.0; 3], emission: [1.0; 3], ..Default::default() };
    let slab = medium("Slab", absorber(sigma));
    for (lo, depth) in [(1.0f32, 1.5f32), (-1.0, 2.5)] {
        let mut desc = scene(
            vec![
                closed_box("Slab", [-20.0, lo, -20.0], [20.0, 2.5, 20.0], 1),
                closed_box("Wall", [-20.0, 5.0, -20.0], [20.0, 6.0, 20.0], 0),
            ],
            vec![wall.clone(), slab.clone()],
            [0.0; 3],
            8,
        );
        desc.camera.projection = gdmlt::scene::desc::Projection::Orthographic;
        desc.camera.ortho_scale = 4.0;
        for (method, nee) in METHODS {
            let (m, e) = mean_and_error(&desc, method, nee, 16, 5);
            let slack = if matches!(method, Method::Pssmlt | Method::Gdpssmlt) { 0.02 } else { 0.0 };
            for c in 0..3 {
                let want = (-(sigma[c] * depth) as f64).exp();
                assert!(
                    (m[c] - want).abs() < 5.0 * e[c] + slack * want + 1e-4,
                    "{method:?} nee={nee}, slab from {lo}: channel {c} {:.4} ± {:.4}, want {want:.4}",
                    m[c],
                    e[c]
                );
            }
        }
    }
}

/// A camera moved into a medium (the viewport's view, `Scene::set_camera`) stands in it: the
/// image is the one of a scene built with the camera there (before, the media were found
/// once at build: the camera moved inside the slab saw the wall through only part of it).
#[test]
fn a_camera_moved_into_a_medium_stands_in_it() {
    let slab = medium(
        "Slab",
        VolumeDesc {
            scattering: [0.2; 3],
            absorption: [0.5, 1.0, 2.0],
            emission: [0.0; 3],
            anisotropy: 0.0,
            density: None,
            ..Default::default()
        },
    );
    let wall = MaterialDesc { name: "Wall".into(), base_color: [0.5; 3], emission: [1.0; 3], ..Default::default() };
    let mut desc = scene(
        vec![
            closed_box("Slab", [-20.0, 1.0, -20.0], [20.0, 2.5, 20.0], 1),
            closed_box("Wall", [-20.0, 5.0, -20.0], [20.0, 6.0, 20.0], 0),
        ],
        vec![wall, slab],
        [0.0; 3],
        8,
    );
    let outside = desc.camera.clone();
    desc.camera = camera_looking_along_y([0.0, 1.5, 0.0], 25.0, 8, 8);
    let inside = desc.camera.clone();
    let fresh = Scene::build(&desc).unwrap();
    desc.camera = outside;
    let mut moved = Scene::build(&desc).unwrap();
    moved.set_camera(gdmlt::scene::Camera::new(&inside).unwrap());
    let settings = RenderSettings { method: Method::Pt, spp: 4, seed: 9, threads: 1, ..Default::default() };
    let image =
        |s: &Scene| render(s, &settings, &RenderControl::new(0.0)).unwrap().layer("Combined").unwrap().data.clone();
    assert_eq!(image(&fresh), image(&moved));
}

/// The World's Volume fills all space: an emitting wall seen by an orthographic camera
/// through a world of absorption σa shows exp(−σa·d) per channel (d the camera's distance to
/// the wall), every method, NEE and naive; and light from infinitely far — the world
/// background behind the wall's gaps — does not get through it (the image is the wall's
/// attenuated light alone, as Cycles renders it).
#[test]
fn a_world_volume_fills_all_space() {
    let sigma = [0.2f32, 0.4, 0.8];
    let wall = MaterialDesc { name: "Wall".into(), base_color: [0.0; 3], emission: [1.0; 3], ..Default::default() };
    let mut desc = scene(vec![closed_box("Wall", [-20.0, 3.0, -20.0], [20.0, 4.0, 20.0], 0)], vec![wall], [5.0; 3], 8);
    desc.camera.projection = gdmlt::scene::desc::Projection::Orthographic;
    desc.camera.ortho_scale = 4.0;
    desc.world_volume = Some(absorber(sigma));
    for (method, nee) in METHODS {
        let (m, e) = mean_and_error(&desc, method, nee, 16, 5);
        let slack = if matches!(method, Method::Pssmlt | Method::Gdpssmlt) { 0.02 } else { 0.0 };
        for c in 0..3 {
            let want = (-(sigma[c] * 3.0) as f64).exp();
            assert!(
                (m[c] - want).abs() < 5.0 * e[c] + slack * want + 1e-4,
                "{method:?} nee={nee}: channel {c} {:.4} ± {:.4}, want {want:.4}",
                m[c],
                e[c]
            );
        }
    }
    // the sky alone (no mesh, no material: the default one is not a medium) is extinguished:
    // black, where it is 5 without the volume (it was 5: the world's medium was taken for
    // the default material's)
    desc.meshes.clear();
    desc.materials.clear();
    let (m, _) = mean_and_error(&desc, Method::Pt, true, 4, 1);
    assert!(m.iter().all(|&x| x == 0.0), "{m:?}");
}
