//! Memory a render will need, estimated before anything is allocated, so that an image too
//! large for the machine is refused with a message instead of an allocation abort.
//!
//! The per-pixel figures are the films and accumulation buffers each method keeps, f32
//! throughout, plus the reconstruction's workspace (peak resident memory above the built
//! scene, `gdmlt_bench scalebench --memory`, 1024² and 1920×1080 Cornell box, one sample,
//! L1; 2026-12-02, gradient-domain methods 2026-12-04 with the α halves): `pt` 105 B (+13 B
//! with adaptive sampling; +12 B since 2026-12-05 for the luminance moments and the
//! "Variance" layer), `gdpt` 157 B, `pssmlt` 69 B, `gdpssmlt` 175 B per pixel,
//! the same on 1 and 2 threads (the Metropolis methods keep one image whatever the thread
//! count; their bootstrap (≤ 4 MB) and splat logs (≤ 6 MB on up to 16 threads) do not grow
//! with the image).

use super::Method;
use crate::error::RenderError;

/// Bytes per pixel each method allocates (rounded up from the measurements above).
pub fn bytes_per_pixel(method: Method) -> u64 {
    match method {
        Method::Pt => 135,
        Method::Gdpt => 170,
        Method::Pssmlt => 90,
        Method::Gdpssmlt => 190,
        // pt's film without the variance moments, plus light tracing's splat sums (12 B)
        Method::Bdpt => 150,
    }
}

/// Estimated bytes for a `width × height` render.
pub fn estimate(method: Method, width: u32, height: u32) -> u64 {
    width as u64 * height as u64 * bytes_per_pixel(method)
}

/// What this process may still allocate: the smaller of the memory the kernel reports as
/// available and what is left of an address-space limit (`ulimit -v`). None where unknown.
pub fn available() -> Option<u64> {
    let meminfo = std::fs::read_to_string("/proc/meminfo").ok();
    let avail = meminfo.as_deref().and_then(|s| field_kib(s, "MemAvailable:")).map(|k| k * 1024);
    let limit = std::fs::read_to_string("/proc/self/limits").ok().and_then(|s| address_space_limit(&s));
    let used =
        std::fs::read_to_string("/proc/self/status").ok().and_then(|s| field_kib(&s, "VmSize:")).map(|k| k * 1024);
    let left = match (limit, used) {
        (Some(l), Some(u)) => Some(l.saturating_sub(u)),
        (Some(l), None) => Some(l),
        _ => None,
    };
    match (avail, left) {
        (Some(a), Some(l)) => Some(a.min(l)),
        (a, l) => a.or(l),
    }
}

fn field_kib(text: &str, key: &str) -> Option<u64> {
    text.lines().find(|l| l.starts_with(key))?.split_whitespace().nth(1)?.parse().ok()
}

/// The soft "Max address space" of /proc/self/limits in bytes (None when unlimited).
fn address_space_limit(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..].split_whitespace().next()?.parse().ok()
}

/// Refuses a render whose estimate exceeds what is available, saying how much and why.
pub fn check(method: Method, width: u32, height: u32, available: Option<u64>) -> Result<(), RenderError> {
    let need = estimate(method, width, height);
    match available {
        Some(have) if need > have => Err(RenderError::Memory(format!(
            "a {width}×{height} {} render needs about {} ({} bytes per pixel) and {} is available; \
             render a smaller image, or split the frame with --partial / --dask",
            method.name(),
            human(need),
            bytes_per_pixel(method),
            human(have)
        ))),
        _ => Ok(()),
    }
}

/// Bytes in GiB or MiB, for messages.
pub fn human(b: u64) -> String {
    let gb = b as f64 / (1u64 << 30) as f64;
    if gb >= 1.0 {
        format!("{gb:.1} GiB")
    } else {
        format!("{:.0} MiB", b as f64 / (1u64 << 20) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 18: a 65536² render aborted the process (SIGABRT) under `ulimit -v 4000000`; it
    /// is now refused up front with the size it needs.
    #[test]
    fn a_render_larger_than_memory_is_refused_with_what_it_needs() {
        let e = check(Method::Gdpssmlt, 65536, 65536, Some(4_000_000 * 1024)).expect_err("refused").to_string();
        assert!(e.contains("65536×65536") && e.contains("GiB") && e.contains("available"), "{e}");
        assert!(check(Method::Pt, 1920, 1080, Some(4_000_000 * 1024)).is_ok());
        assert!(check(Method::Gdpssmlt, 65536, 65536, None).is_ok()); // unknown: not refused
    }

    #[test]
    fn limits_are_read_from_proc_text() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
                      Max address space         4096000000           unlimited            bytes     \n";
        assert_eq!(address_space_limit(limits), Some(4_096_000_000));
        let unlimited = "Max address space         unlimited            unlimited            bytes     \n";
        assert_eq!(address_space_limit(unlimited), None);
        assert_eq!(field_kib("MemTotal: 10 kB\nMemAvailable:   2048 kB\n", "MemAvailable:"), Some(2048));
        assert!(available().is_some()); // this is Linux: /proc is there
    }
}
