//! The hot path allocates nothing per sample: a counting global allocator measures the
//! heap allocations of whole renders at two sample counts; the difference, divided by the
//! extra samples (paths for PT/GDPT, mutations for the Metropolis methods), must be ~0.
//! Per-pass buffers (image rows, previews, the reconstruction) are fixed costs and cancel.

use gdmlt::integrator::{render, Method, RenderControl, RenderSettings};
use gdmlt::path::PathSettings;
use gdmlt::reconstruct::Norm;
use gdmlt::scene::builtin::{cornell_spheres, cornell_veil};
use gdmlt::scene::Scene;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations(scene: &Scene, method: Method, spp: u32) -> usize {
    let settings = RenderSettings {
        method,
        spp,
        path: PathSettings::new(6, true),
        seed: 3,
        threads: 1,
        reconstruction: Norm::L2,
        ..Default::default()
    };
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    render(scene, &settings, &RenderControl::new(0.0)).expect("render");
    ALLOCATIONS.load(Ordering::Relaxed) - before
}

/// Every method on the scenes with the most kinds of vertices (glass, mirror, layered and
/// transparent surfaces, alpha textures). Tests run one at a time here: the counter is global.
#[test]
fn no_allocation_per_sample_on_the_hot_path() {
    let (w, h) = (32u32, 32u32);
    for desc in [cornell_spheres(w, h), cornell_veil(w, h)] {
        let scene = Scene::build(&desc).unwrap();
        for method in [Method::Pt, Method::Gdpt, Method::Pssmlt, Method::Gdpssmlt] {
            let (lo, hi) = (16u32, 64u32);
            allocations(&scene, method, lo); // warm-up: lazily built tables, thread pools
            let (a_lo, a_hi) = (allocations(&scene, method, lo), allocations(&scene, method, hi));
            let extra = (hi - lo) as f64 * (w * h) as f64;
            let per_sample = (a_hi as f64 - a_lo as f64) / extra;
            println!("{method:?}: {a_lo} allocations at {lo}/pixel, {a_hi} at {hi}/pixel: {per_sample:.5} per sample");
            // a few per pass or per round of chains is fine; one per sample would be 1.0
            assert!(per_sample < 0.01, "{method:?} allocates {per_sample:.4} times per sample");
        }
    }
}
