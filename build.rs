//! Stamps the build with a hash of the sources, so that `gdmlt/__init__.py` loads the
//! x86-64-v3 module only when it was built from the same sources as the portable one (a
//! stale `_core_v3` left by an earlier `make build` is ignored, with a warning); and
//! tabulates the GGX albedo tables (src/bsdf/albedo_tables.rs) into $OUT_DIR, so that no
//! render computes them.

#[allow(dead_code)]
#[path = "src/bsdf/microfacet.rs"]
mod microfacet;

#[allow(dead_code)]
#[path = "src/bsdf/albedo_tables.rs"]
mod albedo_tables;

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::Path;

fn walk(dir: &Path, files: &mut Vec<std::path::PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            walk(&p, files);
        } else {
            files.push(p);
        }
    }
}

fn main() {
    let mut files = vec![Path::new("Cargo.toml").to_path_buf(), Path::new("Cargo.lock").to_path_buf()];
    walk(Path::new("src"), &mut files);
    files.sort();
    let mut h = DefaultHasher::new();
    for f in &files {
        f.hash(&mut h);
        std::fs::read(f).unwrap_or_default().hash(&mut h);
    }
    println!("cargo:rustc-env=GDMLT_SOURCE_HASH={:016x}", h.finish());
    write_albedo_tables();
    println!("cargo:rerun-if-changed=src");
    println!("cargo:rerun-if-changed=Cargo.toml");
    println!("cargo:rerun-if-changed=Cargo.lock");
}

/// Every entry of `n`, computed on all the build machine's cores.
fn tabulate(n: usize, entry: fn(usize) -> f32) -> Vec<f32> {
    let threads = std::thread::available_parallelism().map_or(1, |t| t.get()).min(16);
    let chunk = n.div_ceil(threads);
    std::thread::scope(|s| {
        let parts: Vec<_> = (0..threads)
            .map(|t| s.spawn(move || (t * chunk..((t + 1) * chunk).min(n)).map(entry).collect::<Vec<f32>>()))
            .collect();
        parts.into_iter().flat_map(|p| p.join().expect("albedo table thread")).collect()
    })
}

fn write_albedo_tables() {
    use albedo_tables::*;
    let dielectric = tabulate(N_MU * N_ROUGH * N_ETA, dielectric_entry);
    let white = tabulate(N_MU * N_ROUGH_WHITE, white_entry);
    let average = white_averages(&white);
    let glass = tabulate(N_SIDE * N_MU * N_ROUGH * N_ETA, glass_entry);
    let glass_average = hemispherical_averages(&glass);
    let array = |name: &str, v: &[f32]| {
        // Debug formatting of an f32 reads back to the same bits
        format!("pub static {name}: [f32; {}] = {v:?};\n", v.len())
    };
    let text = array("DIELECTRIC", &dielectric)
        + &array("WHITE", &white)
        + &array("WHITE_AVERAGE", &average)
        + &array("GLASS", &glass)
        + &array("GLASS_AVERAGE", &glass_average);
    let out = std::path::PathBuf::from(std::env::var("OUT_DIR").expect("OUT_DIR")).join("albedo_tables.rs");
    std::fs::write(out, text).expect("writing the albedo tables");
}
