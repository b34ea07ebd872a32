//! End-to-end estimator tests on built-in scenes. Tolerances come from the noise measured in
//! the same test (independent renders), not from guesses.

use gdmlt::film::Image;
use gdmlt::integrator::{render, Method, RenderControl, RenderSettings};
use gdmlt::path::PathSettings;
use gdmlt::scene::builtin::{cornell_box, furnace_sphere};
use gdmlt::scene::{Scene, SceneDesc};

fn run(desc: &SceneDesc, spp: u32, nee: bool, max_bounces: u32, seed: u64, threads: usize) -> Image {
    let scene = Scene::build(desc).expect("scene builds");
    let settings = RenderSettings {
        method: Method::Pt,
        spp,
        time_limit: 0.0,
        path: PathSettings { max_bounces, nee },
        seed,
        threads,
    };
    let out = render(&scene, &settings, &RenderControl::new(0.0)).expect("render");
    assert_eq!(out.stats.invalid_samples, 0);
    out.layer("Combined").unwrap().clone()
}

fn mean_and_stderr(img: &Image, channel: usize) -> (f64, f64) {
    let v: Vec<f64> = img.data.iter().skip(channel).step_by(3).map(|&x| x as f64).collect();
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// Inside a closed sphere of uniform emission Le and albedo ρ the radiance is the same
/// everywhere: L = Le·Σ_{k=0}^{B+1} ρ^k with B max bounces (B+2 path vertices can emit).
/// Pixels are independent estimates of the same value, so their spread gives the error bar.
#[test]
fn furnace_sphere_converges_to_analytic_radiance() {
    for (albedo, bounces) in [(0.8f32, 8u32), (1.0, 3), (0.5, 0)] {
        let desc = furnace_sphere(albedo, 1.0, 24, 24);
        let expected: f64 = (0..=bounces + 1).map(|k| (albedo as f64).powi(k as i32)).sum();
        for nee in [false, true] {
            let img = run(&desc, 32, nee, bounces, 5, 0);
            let (m, se) = mean_and_stderr(&img, 1);
            assert!(
                (m - expected).abs() < 5.0 * se + 1e-3 * expected,
                "albedo {albedo} bounces {bounces} nee {nee}: mean {m} ± {se}, expected {expected}"
            );
        }
    }
}

fn block_means(img: &Image, b: usize) -> Vec<f64> {
    let mut out = Vec::new();
    for by in 0..img.height / b {
        for bx in 0..img.width / b {
            for c in 0..3 {
                let mut s = 0.0;
                for y in by * b..(by + 1) * b {
                    for x in bx * b..(bx + 1) * b {
                        s += img.data[(y * img.width + x) * 3 + c] as f64;
                    }
                }
                out.push(s / (b * b) as f64);
            }
        }
    }
    out
}

/// Next-event estimation with MIS and naive path tracing estimate the same image: the
/// difference NEE − naive must look like noise, judged against the difference of two
/// naive renders with different seeds (whose variance is at least as large).
#[test]
fn nee_and_naive_path_tracing_agree_on_cornell_box() {
    let desc = cornell_box(32, 32);
    let nee = block_means(&run(&desc, 256, true, 6, 1, 0), 4);
    let naive_a = block_means(&run(&desc, 512, false, 6, 2, 0), 4);
    let naive_b = block_means(&run(&desc, 512, false, 6, 3, 0), 4);
    let rms = |v: &Vec<f64>| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    let d: Vec<f64> = nee.iter().zip(&naive_a).map(|(a, b)| a - b).collect();
    let e: Vec<f64> = naive_a.iter().zip(&naive_b).map(|(a, b)| a - b).collect();
    let (rd, re) = (rms(&d), rms(&e));
    assert!(rd < 1.3 * re, "NEE−naive rms {rd} vs naive−naive rms {re}");
    // A bias shows in the mean over blocks: its standard error is ≈ re/sqrt(n).
    let mean_d = d.iter().sum::<f64>() / d.len() as f64;
    assert!(mean_d.abs() < 4.0 * re / (d.len() as f64).sqrt(), "mean difference {mean_d} (noise rms {re})");
    // the image is not black
    assert!(naive_a.iter().sum::<f64>() / naive_a.len() as f64 > 0.05);
}

#[test]
fn output_is_independent_of_thread_count() {
    let desc = cornell_box(16, 12);
    let a = run(&desc, 4, true, 4, 9, 1);
    let b = run(&desc, 4, true, 4, 9, 2);
    assert_eq!(a.data, b.data);
    let c = run(&desc, 4, true, 4, 10, 2);
    assert_ne!(a.data, c.data, "a different seed must give a different image");
}

#[test]
fn cancel_and_time_limit_stop_the_render() {
    let scene = Scene::build(&cornell_box(64, 64)).unwrap();
    let settings = RenderSettings { spp: 1_000_000, time_limit: 0.3, ..Default::default() };
    let t = std::time::Instant::now();
    let out = render(&scene, &settings, &RenderControl::new(settings.time_limit)).unwrap();
    assert!(t.elapsed().as_secs_f64() < 2.0, "time limit ignored: {:?}", t.elapsed());
    assert!(out.stats.spp_max >= 1 && out.stats.spp_max < 1_000_000);
    let ctl = RenderControl::new(0.0);
    ctl.cancel();
    let out = render(&scene, &settings, &ctl).unwrap();
    assert!(out.stats.cancelled);
    assert_eq!(out.stats.spp_max, 0);
}

#[test]
fn bad_input_is_an_error_naming_the_object() {
    let mut desc = cornell_box(8, 8);
    desc.meshes[2].positions[1][0] = f32::NAN;
    let err = Scene::build(&desc).err().expect("NaN vertex must be rejected").to_string();
    assert!(err.contains("BackWall") && err.contains("NaN"), "{err}");
    let mut desc = cornell_box(8, 8);
    desc.meshes[0].indices[0][2] = 99;
    assert!(Scene::build(&desc).err().unwrap().to_string().contains("Floor"));
    let mut desc = cornell_box(8, 8);
    desc.camera.resolution_x = 0;
    assert!(Scene::build(&desc).is_err());
}

#[test]
fn degenerate_triangles_and_empty_scenes_render_finite() {
    let mut desc = cornell_box(8, 8);
    desc.meshes[0].positions[2] = desc.meshes[0].positions[1]; // collapses one triangle
    let scene = Scene::build(&desc).unwrap();
    assert_eq!(scene.report.degenerate_triangles, 1);
    assert!(!scene.report.warnings.is_empty());
    let empty = SceneDesc { camera: desc.camera.clone(), ..Default::default() };
    let scene = Scene::build(&empty).unwrap();
    assert!(scene.report.warnings.iter().any(|w| w.contains("no light")));
    let out = render(&scene, &RenderSettings { spp: 2, ..Default::default() }, &RenderControl::new(0.0)).unwrap();
    assert!(out.layer("Combined").unwrap().data.iter().all(|&x| x == 0.0));
}
