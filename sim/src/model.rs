//! The sensor model (thesis §3.2, §5.3): the source fibres set up once; `tracer.rs` traces
//! its accretions.

use glam::{DVec2, DVec3};
use rand_pcg::Pcg32;

pub use crate::config::{
    Coupling, DiffuseFresnel, IceKind, IceParams, SensorKind, SimConfig, SimError,
};
use crate::consts::*;
pub use crate::curve::{Curve, CurvePoint};
use crate::kernels::LANES;
use crate::laws::{fr_dielectric, fresnel_transmittance, refract, theta_max, theta_max_fibre};
use crate::setup::RayLanes;
use crate::streams::{mix64, std_normal, uniform};
use crate::walk::GapSampler;

/// One source fibre's ray, fixed at model set-up.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SourceRay {
    /// Position on the face, mm.
    pub(crate) p0: DVec2,
    /// Direction in the medium (unit, z > 0).
    pub(crate) dir: DVec3,
    /// Flux that enters the medium: Φ_ray · T(fibre→medium), W.
    pub(crate) flux_in_w: f64,
    /// Flux reflected at a dry fibre/air face, W (Sensor A leak).
    pub(crate) refl_air_w: f64,
    /// Flux reflected at the fibre/medium face, W (Sensor A leak under ice).
    pub(crate) refl_med_w: f64,
}

/// The sensor with its fibres set up: trace accretions with it.
#[derive(Clone, Debug)]
pub struct SensorModel {
    pub(crate) cfg: SimConfig,
    pub(crate) rays: Vec<SourceRay>,
    /// The rays' positions and directions as a structure of arrays (the set-up's kernels).
    pub(crate) ray_lanes: RayLanes,
    pub(crate) thick: Vec<f64>,
    /// The thicknesses continued on their grid by `kernels::LANES` more: the kernels' padded
    /// lanes read them (and their outputs are never used).
    pub(crate) thick_lanes: Vec<f64>,
    /// sin and cos of half the largest diffuse angle, δ_max/2.
    pub(crate) half_diffuse_sin_cos: (f64, f64),
    /// Unit vector along the signal fibres' axis (pointing into the medium).
    fibre_axis: DVec3,
    cos_accept: f64,
    /// Dense bubbles (rime) walk gap by gap from counter-based streams (bubbles.rs).
    pub(crate) dense: Option<GapSampler>,
}

/// Above this P_B the bubbles are walked by `walk::GapSampler` from counter-based
/// streams; at or below it by `geometric_gap` (one `ln` per bubble) from a PCG stream.
const DENSE_ABOVE: f64 = 0.02;

impl SensorModel {
    /// Set up the sensor: source fibres on their grid, fibre angles θ_f ~ N(0, θ_max/5)
    /// clipped to ±θ_max,f with a uniform azimuth (eqs. 3.17–3.20), drawn from `fibre_seed`.
    ///
    /// # Panics
    /// If `cfg.validate()` fails (e.g. a zero step): check user input with `validate` first.
    pub fn new(cfg: &SimConfig) -> Self {
        if let Err(e) = cfg.validate() {
            panic!("invalid SimConfig: {e}");
        }
        let n_med = cfg.params.n_medium;
        let th_max = theta_max(NA, N_AIR); // (3.17)
        let th_max_f = theta_max_fibre(th_max, N_AIR, N_FIBRE); // (3.18)
        let sigma = th_max / 5.0;
        let grid = cfg.geometry.source_grid_mm();
        let flux_ray = SOURCE_FLUX_W / grid.len() as f64;
        let mut rng = Pcg32::new(mix64(cfg.fibre_seed), 1);
        let incl = INCLINATION_DEG.to_radians();
        let (si, ci) = incl.sin_cos();
        let face_in = DVec3::new(0.0, 0.0, -1.0); // normal on the fibre side
        let rays = grid
            .into_iter()
            .map(|(x, y)| {
                let (th_f, beta) = if cfg.fibre_spread {
                    let th = (sigma * std_normal(&mut rng)).clamp(-th_max_f, th_max_f);
                    (th, std::f64::consts::TAU * uniform(&mut rng))
                } else {
                    (0.0, 0.0)
                };
                // Direction inside an upright fibre (Fig. 3.15) ...
                let (st, ct) = th_f.sin_cos();
                let f = DVec3::new(st * beta.cos(), st * beta.sin(), ct);
                // ... turned toward +x by the inclination about y: eq. 3.20 in 3-D
                // (θ_i,x = θ_f,x + θ_Incl for rays in the x–z plane).
                let fi = DVec3::new(f.x * ci + f.z * si, f.y, -f.x * si + f.z * ci);
                let cos_i = fi.z;
                let (dir, t) = match refract(fi, face_in, N_FIBRE, n_med) {
                    Some(d) => (d, fresnel_transmittance(cos_i, N_FIBRE, n_med)),
                    None => (DVec3::Z, 0.0),
                };
                SourceRay {
                    p0: DVec2::new(x, y),
                    dir,
                    flux_in_w: flux_ray * t,
                    refl_air_w: flux_ray * fr_dielectric(cos_i, N_FIBRE, N_AIR),
                    refl_med_w: flux_ray * fr_dielectric(cos_i, N_FIBRE, n_med),
                }
            })
            .collect::<Vec<SourceRay>>();
        SensorModel {
            cfg: cfg.clone(),
            ray_lanes: RayLanes::new(rays.iter().map(|r| (r.p0, r.dir))),
            rays,
            thick: cfg.thicknesses_mm(),
            half_diffuse_sin_cos: (0.5 * cfg.params.diffuse_max_rad).sin_cos(),
            thick_lanes: cfg.thickness_grid_mm(LANES),
            fibre_axis: DVec3::new(si, 0.0, ci),
            cos_accept: th_max_f.cos(),
            dense: (cfg.params.p_bubble > DENSE_ABOVE)
                .then(|| GapSampler::new(cfg.params.p_bubble)),
        }
    }

    /// Number of source rays.
    pub fn n_rays(&self) -> usize {
        self.rays.len()
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Number of ray evaluations (rays × thicknesses) of one accretion.
    pub fn ray_evaluations(&self) -> u64 {
        self.rays.len() as u64 * self.thick.len() as u64
    }

    /// Fraction of a downward ray (direction `s`, s.z < 0) that enters a signal fibre
    /// (eqs. 3.24–3.25 with the Fresnel transmittance, plus the optional acceptance cone).
    #[inline]
    pub(crate) fn couple(&self, s: DVec3) -> f64 {
        let n_med = self.cfg.params.n_medium;
        let cos_i = -s.z;
        self.couple_transmitted(s, fresnel_transmittance(cos_i, n_med, N_FIBRE))
    }

    /// [`SensorModel::couple`] with the Fresnel transmittance `t` into the fibre already
    /// known: `t`, or 0 outside the acceptance cone when that coupling is chosen.
    #[inline]
    pub(crate) fn couple_transmitted(&self, s: DVec3, t: f64) -> f64 {
        match self.cfg.coupling {
            Coupling::ThesisLiteral => t,
            Coupling::AcceptanceCone if self.in_acceptance_cone(s) => t,
            Coupling::AcceptanceCone => 0.0,
        }
    }

    /// Whether a downward ray `s` refracted into a signal fibre lies inside its guided cone
    /// (θ_max,f, eq. 3.18, around the fibre axis): `Coupling::AcceptanceCone`.
    pub(crate) fn in_acceptance_cone(&self, s: DVec3) -> bool {
        match refract(s, DVec3::Z, self.cfg.params.n_medium, N_FIBRE) {
            Some(tr) => tr.dot(-self.fibre_axis) >= self.cos_accept,
            None => false,
        }
    }
}

/// One physical accretion of `cfg`, deterministic in (seed, run).
///
/// # Panics
/// If `cfg.validate()` fails.
pub fn accretion_curve(cfg: &SimConfig, seed: u64, run: u64) -> Curve {
    SensorModel::new(cfg).accretion(seed, run)
}
