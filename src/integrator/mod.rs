//! Integrators decide which paths to build and where their contributions go; path
//! construction itself lives in path.rs. This module holds what they share: settings,
//! halting, progress and cancellation, and the output.

pub mod adaptive;
pub mod bdpt;
pub mod gdpt;
pub mod memory;
pub mod mlt;
pub mod passes;
pub mod pt;

use crate::error::RenderError;
use crate::film::Image;
use crate::path::PathSettings;
use crate::reconstruct::Norm;
use crate::scene::Scene;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    Pt,
    Gdpt,
    Pssmlt,
    Gdpssmlt,
    Bdpt,
}

impl Method {
    pub fn parse(s: &str) -> Result<Method, RenderError> {
        match s.to_ascii_lowercase().as_str() {
            "pt" => Ok(Method::Pt),
            "gdpt" => Ok(Method::Gdpt),
            "pssmlt" => Ok(Method::Pssmlt),
            "gdpssmlt" => Ok(Method::Gdpssmlt),
            "bdpt" => Ok(Method::Bdpt),
            other => Err(RenderError::Settings(format!(
                "unknown method '{other}' (expected pt, bdpt, gdpt, pssmlt or gdpssmlt)"
            ))),
        }
    }
    pub fn name(&self) -> &'static str {
        match self {
            Method::Pt => "pt",
            Method::Gdpt => "gdpt",
            Method::Pssmlt => "pssmlt",
            Method::Gdpssmlt => "gdpssmlt",
            Method::Bdpt => "bdpt",
        }
    }
}

#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub method: Method,
    /// Samples per pixel (path tracing) or mutations per pixel (Metropolis).
    pub spp: u32,
    /// Wall-clock limit in seconds; 0 = none. The render halts on whichever comes first.
    pub time_limit: f64,
    pub path: PathSettings,
    pub seed: u64,
    /// Worker threads; 0 = all cores.
    pub threads: usize,
    /// Gradient-domain methods: reconstruction norm and screened-Poisson weight α; α = 0
    /// (the default) measures it from the render's own noise (reconstruct/alpha.rs).
    pub reconstruction: Norm,
    pub alpha_rec: f64,
    /// Metropolis methods: probability of a large step (Kelemen), default 0.5 (measured
    /// against Kelemen's 0.3: lower 8×8 block error on every scene tried, docs/algorithm.md
    /// §2), and the weight α of the primal term in gdpssmlt's target function.
    pub large_step_probability: f32,
    pub alpha_target: f32,
    /// Metropolis methods: number of Markov chains; 0 = one per 2000 mutations (1 to 1024).
    pub chains: u32,
    /// Metropolis methods: how chains pick their start among the bootstrap samples.
    pub chain_start: ChainStart,
    /// Add the Depth and Position passes (passes.rs).
    pub data_passes: bool,
    /// `pt`: adaptive sampling's noise threshold (adaptive.rs; 0 = off, every pixel gets
    /// `spp`) and the samples every pixel takes before any stops (0 = automatic).
    pub adaptive_threshold: f32,
    pub adaptive_min_samples: u32,
    /// `pt`: path guiding (guiding/mod.rs), learned during the render.
    pub guiding: bool,
    /// `pssmlt`: each Markov state is a whole bidirectional sample (integrator/bdpt.rs, every
    /// strategy) instead of a camera path.
    pub bidirectional: bool,
    /// `bdpt`: also estimate, from its own samples, what `pt` would make of each pixel —
    /// the second moment of its estimator ("PT Second Moment") and the light it cannot
    /// make at all ("PT Unsampled"): the automatic method's pilot reads `pt`'s heavy tails
    /// there, which its own short renders of `pt` rarely see (python/gdmlt/auto.py).
    /// Default false; other methods ignore it.
    pub predict_pt: bool,
}

/// Where Metropolis chains start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ChainStart {
    /// A bootstrap sample drawn ∝ its target value (unbiased start, the default).
    #[default]
    Proportional,
    /// The dimmest bootstrap sample that carries any light (a test of ergodicity: the
    /// chains must still find the bright parts of the image).
    Dimmest,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            method: Method::Pt,
            spp: 16,
            time_limit: 0.0,
            path: PathSettings::default(),
            seed: 0,
            threads: 0,
            reconstruction: Norm::L1,
            alpha_rec: 0.0,
            large_step_probability: 0.5,
            alpha_target: 1.0,
            chains: 0,
            chain_start: ChainStart::Proportional,
            data_passes: false,
            adaptive_threshold: 0.0,
            adaptive_min_samples: 0,
            guiding: false,
            bidirectional: false,
            predict_pt: false,
        }
    }
}

impl RenderSettings {
    pub fn validate(&self) -> Result<(), RenderError> {
        if self.spp == 0 {
            return Err(RenderError::Settings("samples must be at least 1".into()));
        }
        if !self.time_limit.is_finite() || self.time_limit < 0.0 {
            return Err(RenderError::Settings("time limit must be a finite number of seconds ≥ 0".into()));
        }
        let p = &self.path;
        for (what, n) in [
            ("max bounces", p.max_bounces),
            ("diffuse bounces", p.diffuse_bounces),
            ("glossy bounces", p.glossy_bounces),
            ("transmission bounces", p.transmission_bounces),
            ("volume bounces", p.volume_bounces),
            ("transparent bounces", p.transparent_bounces),
        ] {
            if n > 1024 {
                return Err(RenderError::Settings(format!("{what} must be at most 1024")));
            }
        }
        for (what, v) in [("clamp direct", p.clamp_direct), ("clamp indirect", p.clamp_indirect)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(RenderError::Settings(format!("{what} must be a finite number ≥ 0 (0 = off)")));
            }
        }
        if !(self.alpha_rec.is_finite() && self.alpha_rec >= 0.0) {
            return Err(RenderError::Settings(
                "reconstruction alpha must be a finite number ≥ 0 (0 = automatic)".into(),
            ));
        }
        if !(0.0..=1.0).contains(&self.large_step_probability) {
            return Err(RenderError::Settings("large step probability must be in [0, 1]".into()));
        }
        // α = 0 would leave the primal unsampled wherever the gradients vanish (a flat, evenly
        // lit wall has F = 0 there: biased), so the target keeps a share of the primal
        if !(self.alpha_target.is_finite() && self.alpha_target > 0.0) {
            return Err(RenderError::Settings("target alpha must be a finite number > 0".into()));
        }
        if !(self.adaptive_threshold.is_finite() && (0.0..=1.0).contains(&self.adaptive_threshold)) {
            return Err(RenderError::Settings("noise threshold must be in [0, 1] (0 = adaptive sampling off)".into()));
        }
        if self.adaptive_min_samples > 1 << 24 {
            return Err(RenderError::Settings("adaptive min samples must be at most 16777216".into()));
        }
        if self.chains > 1_000_000 {
            return Err(RenderError::Settings("chains must be at most 1000000".into()));
        }
        if self.threads > 1024 {
            return Err(RenderError::Settings("threads must be at most 1024".into()));
        }
        Ok(())
    }
}

/// Shared between the render and whoever watches it (the Python binding polls it).
pub struct RenderControl {
    cancel: AtomicBool,
    pub work_done: AtomicU64,
    pub work_total: AtomicU64,
    start: Instant,
    time_limit: Option<Duration>,
    /// Set by a watcher that wants an intermediate image; the integrator answers between
    /// passes (rounds) by putting one into `preview`.
    preview_requested: AtomicBool,
    preview: Mutex<Option<Image>>,
}

impl RenderControl {
    pub fn new(time_limit: f64) -> RenderControl {
        RenderControl {
            cancel: AtomicBool::new(false),
            work_done: AtomicU64::new(0),
            work_total: AtomicU64::new(1),
            start: Instant::now(),
            // a limit past what a Duration holds (≈ 5.8e11 years; e.g. 1e20 s) is no limit
            time_limit: if time_limit > 0.0 { Duration::try_from_secs_f64(time_limit).ok() } else { None },
            preview_requested: AtomicBool::new(false),
            preview: Mutex::new(None),
        }
    }
    /// Asks the render for an intermediate "Combined" image at its next pass boundary.
    pub fn request_preview(&self) {
        self.preview_requested.store(true, Ordering::Relaxed);
    }
    /// The intermediate image produced since the last call, if any.
    pub fn take_preview(&self) -> Option<Image> {
        self.preview.lock().ok()?.take()
    }
    /// For integrators: if a preview is wanted, build it with `make` and hand it over.
    pub fn offer_preview(&self, make: impl FnOnce() -> Image) {
        if self.preview_requested.swap(false, Ordering::Relaxed) {
            let img = make();
            if let Ok(mut slot) = self.preview.lock() {
                *slot = Some(img);
            }
        }
    }
    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }
    pub fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
    pub fn out_of_time(&self) -> bool {
        self.time_limit.is_some_and(|t| self.start.elapsed() >= t)
    }
    /// The reconstruction to finish with: the requested one, or after a cancel the exact L2
    /// solve (0.4 s at 1920×1080 against L1's 2.3 s on 2 cores), so that Esc is answered at once with
    /// the image so far.
    pub fn final_norm(&self, requested: crate::reconstruct::Norm) -> crate::reconstruct::Norm {
        if self.is_cancelled() {
            crate::reconstruct::Norm::L2
        } else {
            requested
        }
    }

    /// Stop now: cancelled by the user or out of time.
    #[inline]
    pub fn should_stop(&self) -> bool {
        self.is_cancelled() || self.out_of_time()
    }
    pub fn elapsed(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// The samples per pixel of the next whole pass over the image: `wanted`, but no more
    /// than fit in the time left at `seconds_per_sample` (the last pass's rate), and 0 when
    /// not even half a sample does — a pass is not cut short, so without this the last one
    /// overran a short time limit by up to its whole length (a 0.03 s gdpt pilot render took
    /// 0.05 s).
    pub fn samples_fitting(&self, wanted: u32, seconds_per_sample: f64) -> u32 {
        match self.time_limit {
            None => wanted,
            Some(limit) => samples_fitting(wanted, limit.as_secs_f64() - self.elapsed(), seconds_per_sample),
        }
    }
    /// Fraction of the halt condition reached (samples or time, whichever is further).
    pub fn progress(&self) -> f64 {
        let by_work =
            self.work_done.load(Ordering::Relaxed) as f64 / self.work_total.load(Ordering::Relaxed).max(1) as f64;
        let by_time = self.time_limit.map_or(0.0, |t| self.start.elapsed().as_secs_f64() / t.as_secs_f64());
        by_work.max(by_time).min(1.0)
    }
}

/// `RenderControl::samples_fitting` with `left` seconds to go.
fn samples_fitting(wanted: u32, left: f64, seconds_per_sample: f64) -> u32 {
    if !(seconds_per_sample > 0.0) {
        return wanted;
    }
    let fit = left / seconds_per_sample;
    if fit < 0.5 {
        0
    } else {
        wanted.min(fit.round().max(1.0) as u32)
    }
}

#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    pub method: &'static str,
    pub elapsed: f64,
    pub spp_min: u32,
    pub spp_max: u32,
    pub invalid_samples: u64,
    pub cancelled: bool,
    pub warnings: Vec<String>,
    /// Metropolis methods: acceptance rate, normalisation b = E[F], number of chains.
    pub acceptance: f64,
    pub normalization: f64,
    pub chains: usize,
    /// Metropolis methods: true where direct light came from the Monte Carlo direct pass and
    /// the chains rendered the rest; false where the chains rendered all light but the
    /// camera-seen emission (direct light too hard for plain Monte Carlo).
    pub direct_pass: bool,
    /// Metropolis methods: the relative variance of one direct-light sample (camera-seen
    /// emission aside) by which `direct_pass` was decided; 0 where no direct light was seen.
    pub direct_relative_variance: f64,
    /// Gradient-domain methods: the reconstruction's α (the setting, or the measured one).
    pub alpha_rec: f64,
    /// `pt` with path guiding: training iterations completed and the guide's spatial regions.
    pub guide_iterations: u32,
    pub guide_regions: usize,
    /// `pt`: the mean number of segments (closest-hit rays) per path, camera ray included —
    /// what samples per second compare at (benchmarks print it beside them); 0 elsewhere.
    pub mean_path_segments: f64,
}

/// Named images: "Combined" first, then passes.
pub struct RenderOutput {
    pub layers: Vec<(String, Image)>,
    pub stats: RenderStats,
}

impl RenderOutput {
    pub fn layer(&self, name: &str) -> Option<&Image> {
        self.layers.iter().find(|(n, _)| n == name).map(|(_, i)| i)
    }
}

/// Renders `scene` with the chosen method on a thread pool of the requested size.
pub fn render(scene: &Scene, settings: &RenderSettings, control: &RenderControl) -> Result<RenderOutput, RenderError> {
    settings.validate()?;
    memory::check(settings.method, scene.camera.width, scene.camera.height, memory::available())?;
    let mut builder = rayon::ThreadPoolBuilder::new();
    if settings.threads > 0 {
        builder = builder.num_threads(settings.threads);
    }
    let pool = builder.build().map_err(|e| RenderError::Settings(format!("thread pool: {e}")))?;
    let mut warnings = scene.report.warnings.clone();
    let clamped = settings.path.clamp_direct > 0.0 || settings.path.clamp_indirect > 0.0;
    let mut unclamped = settings.clone();
    let settings = if clamped && matches!(settings.method, Method::Gdpt | Method::Gdpssmlt) {
        // the shift mapping evaluates unclamped contributions: a clamped primal and very-direct
        // image beside unclamped gradients would not reconstruct one image
        warnings.push(format!(
            "clamping (direct/indirect) is not applied by {}: its gradients are unclamped; pt and pssmlt clamp",
            settings.method.name()
        ));
        (unclamped.path.clamp_direct, unclamped.path.clamp_indirect) = (0.0, 0.0);
        &unclamped
    } else {
        settings
    };
    if settings.bidirectional && settings.method != Method::Pssmlt {
        warnings.push(format!(
            "bidirectional Markov states apply to pssmlt only; {} renders without them",
            settings.method.name()
        ));
    }
    if settings.guiding && settings.method != Method::Pt {
        warnings.push(format!("path guiding applies to pt only; {} renders without it", settings.method.name()));
    }
    if !settings.path.nee {
        let delta = scene.delta_lights();
        if !delta.is_empty() {
            warnings.push(format!(
                "naive path tracing (NEE off) cannot hit point lights without radius or suns without angle; they add nothing: {}",
                delta.join(", ")
            ));
        }
    }
    let mut out = pool.install(|| match settings.method {
        Method::Pt => Ok(pt::render(scene, settings, control)),
        Method::Gdpt => Ok(gdpt::render(scene, settings, control)),
        Method::Pssmlt => Ok(mlt::render(scene, settings, control, false)),
        Method::Gdpssmlt => Ok(mlt::render(scene, settings, control, true)),
        Method::Bdpt => Ok(bdpt::render(scene, settings, control)),
    })?;
    if settings.data_passes {
        out.layers.extend(pool.install(|| passes::data_passes(scene, settings.seed)));
    }
    if let Some(backdrop) = scene.camera.backdrop {
        composite_backdrop(&mut out, backdrop);
    }
    out.stats.warnings.splice(0..0, warnings);
    out.stats.cancelled = control.is_cancelled();
    Ok(out)
}

/// Puts the camera's backdrop behind the image: Combined += (1 − α)·backdrop, with α the
/// transparent film's alpha the render made for it (the share of camera rays that leave the
/// scene, through transparent surfaces too); that Alpha layer is then dropped.
fn composite_backdrop(out: &mut RenderOutput, backdrop: crate::math::Spectrum) {
    let Some(i) = out.layers.iter().position(|(name, _)| name == "Alpha") else { return };
    let (_, alpha) = out.layers.remove(i);
    if let Some((_, combined)) = out.layers.iter_mut().find(|(name, _)| name == "Combined") {
        for (px, a) in combined.data.chunks_exact_mut(3).zip(&alpha.data) {
            let seen = 1.0 - a;
            px[0] += seen * backdrop.x;
            px[1] += seen * backdrop.y;
            px[2] += seen * backdrop.z;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reconstruct::Norm;

    /// After an Esc the render finishes with the fast exact L2 solve; a time limit keeps the
    /// requested reconstruction (the user asked for that image).
    #[test]
    fn a_cancelled_render_finishes_with_l2_and_a_timed_one_as_asked() {
        let timed = RenderControl::new(1e-9);
        std::thread::sleep(std::time::Duration::from_millis(2));
        assert!(timed.should_stop() && !timed.is_cancelled());
        assert_eq!(timed.final_norm(Norm::L1), Norm::L1);
        let esc = RenderControl::new(0.0);
        assert_eq!(esc.final_norm(Norm::L1), Norm::L1);
        esc.cancel();
        assert_eq!(esc.final_norm(Norm::L1), Norm::L2);
    }

    /// Issue 18: a time limit past what a Duration holds (1e20 s) panicked outside the
    /// render's panic guard (the CLI then wrote a black frame and exited 0); it is no limit.
    /// The last whole pass is cut to the time left: as many samples as fit (rounded, at least
    /// one), none when not even half of one does, all that were wanted when they fit or when
    /// the rate is unknown.
    #[test]
    fn a_pass_takes_only_the_samples_that_fit_in_the_time_left() {
        assert_eq!(samples_fitting(32, 0.010, 0.001), 10);
        assert_eq!(samples_fitting(32, 1.0, 0.001), 32);
        assert_eq!(samples_fitting(32, 0.0012, 0.001), 1);
        assert_eq!(samples_fitting(32, 0.0004, 0.001), 0);
        assert_eq!(samples_fitting(32, -0.5, 0.001), 0);
        assert_eq!(samples_fitting(8, 0.010, 0.0), 8);
        assert_eq!(RenderControl::new(0.0).samples_fitting(16, 1e9), 16); // no time limit
    }

    #[test]
    fn a_time_limit_beyond_a_duration_is_no_limit() {
        for t in [1e20, f64::MAX] {
            let c = RenderControl::new(t);
            assert!(!c.should_stop());
        }
    }

    /// A target without primal share (α = 0) is refused: it leaves evenly lit regions
    /// unsampled (accepted before); any α > 0 is fine.
    #[test]
    fn a_target_alpha_of_zero_is_refused() {
        let with = |alpha_target| RenderSettings { alpha_target, ..Default::default() }.validate();
        assert!(matches!(with(0.0), Err(RenderError::Settings(m)) if m.contains("target alpha")));
        assert!(with(-1.0).is_err() && with(f32::NAN).is_err());
        assert!(with(0.05).is_ok() && with(1.0).is_ok());
    }
}
