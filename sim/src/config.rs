//! The simulation's configuration: the medium and its parameters, the sensor construction,
//! the coupling and diffuse-Fresnel choices, the thickness grid (thesis §3.4, §5.2, §5.3).

use crate::consts::*;
use crate::geometry::Geometry;

/// The medium that accretes on the face (thesis §3.4, §5.2.3, §5.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IceKind {
    /// Ideal clear ice: flat surface, no bubbles, no diffuse reflection (§3.3).
    Flat,
    /// Glazed ice: δ_S ~ U(±15°), P_B = 0.0015, δ_R ~ U(±30°) (§5.3.3, Fig. 5.14).
    Glazed,
    /// Rime ice: δ_S ~ U(±10°), P_B = 0.21, δ_R = 0 (§5.3.4).
    Rime,
    /// Clear water: n = 1.33, flat, no bubbles (§5.2.3).
    Water,
}

impl IceKind {
    /// The model parameters of this medium.
    pub fn params(self) -> IceParams {
        let deg = std::f64::consts::PI / 180.0;
        match self {
            IceKind::Flat => IceParams {
                n_medium: N_ICE,
                p_bubble: 0.0,
                slope_max_rad: 0.0,
                diffuse_max_rad: 0.0,
            },
            IceKind::Glazed => IceParams {
                n_medium: N_ICE,
                p_bubble: 0.0015,
                slope_max_rad: 15.0 * deg,
                diffuse_max_rad: 30.0 * deg,
            },
            IceKind::Rime => IceParams {
                n_medium: N_ICE,
                p_bubble: 0.21,
                slope_max_rad: 10.0 * deg,
                diffuse_max_rad: 0.0,
            },
            IceKind::Water => IceParams {
                n_medium: N_WATER,
                p_bubble: 0.0,
                slope_max_rad: 0.0,
                diffuse_max_rad: 0.0,
            },
        }
    }

    /// Name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            IceKind::Flat => "flat",
            IceKind::Glazed => "glazed",
            IceKind::Rime => "rime",
            IceKind::Water => "water",
        }
    }
}

/// Parameters of the accreted medium. `IceKind::params` gives the thesis presets; change
/// them in a `SimConfig` for studies (e.g. glazed ice without diffuse reflection, Fig. 5.13).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IceParams {
    /// Refractive index of the medium.
    pub n_medium: f64,
    /// Probability P_B that a ray meets a bubble in one layer of `BUBBLE_LAYER_MM`.
    pub p_bubble: f64,
    /// Surface slopes δ_S ~ U(±slope_max) in x and in y, drawn once per accretion, rad.
    pub slope_max_rad: f64,
    /// Diffuse deflection δ_R ~ U(±diffuse_max) of each reflected ray, drawn per ray per
    /// surface (i.e. per new layer), rad.
    pub diffuse_max_rad: f64,
}

/// Sensor construction (thesis §4.4, §5.2.1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum SensorKind {
    /// Transparent separation between the bundles: light reflected at the fibre face leaks
    /// into the signal bundles, giving a dry offset (thesis §5.2.1, Fig. 5.5).
    A,
    /// Opaque separation: no leak, a dry face reads ~0 (Fig. 5.6). The thesis's rime sensor.
    #[default]
    B,
}

/// How a returning ray couples into a signal fibre.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Coupling {
    /// Thesis-literal (eqs. 3.24–3.25): any ray landing on a bundle enters with the Fresnel
    /// transmittance at its refraction angle.
    #[default]
    ThesisLiteral,
    /// Additionally require that the refracted ray lies inside the guided cone (θ_max,f,
    /// eq. 3.18) around the signal fibres' axis, which leans toward +x by the inclination
    /// like the source fibres. Rejects almost every specular return (see README).
    AcceptanceCone,
}

/// At which angle the Fresnel reflectance of a diffusely reflected ray is taken.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DiffuseFresnel {
    /// At the micro-facet's angle of incidence (physical; beyond 49.8° the ray reflects
    /// totally). The default.
    #[default]
    Facet,
    /// At the angle of incidence on the mean (tilted) surface, the diffuse angle only
    /// deflecting the ray — one reading of thesis eqs. 3.22–3.23; it makes diffuse reflection
    /// lower the glazed levels as in thesis Fig. 5.14.
    MeanSurface,
}

/// Configuration of a simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig {
    /// The accreted medium.
    pub ice: IceKind,
    /// Sensor construction.
    pub sensor: SensorKind,
    /// Face geometry.
    pub geometry: Geometry,
    /// Largest thickness, mm (default 15).
    pub max_mm: f64,
    /// Thickness step of the output curve, mm (default 0.1).
    pub step_mm: f64,
    /// Medium parameters (defaults from `ice.params()`).
    pub params: IceParams,
    /// Coupling model (default thesis-literal).
    pub coupling: Coupling,
    /// Draw the fibre angles θ_f (default true); false: every fibre emits along its axis.
    pub fibre_spread: bool,
    /// Seed of the fibre angles, drawn once per model set-up (the sensor), not per accretion.
    pub fibre_seed: u64,
    /// Fresnel angle of diffusely reflected rays (default: the facet's).
    pub diffuse_fresnel: DiffuseFresnel,
}

impl SimConfig {
    /// The thesis parameters for this medium, sensor and geometry; 0–15 mm in 0.1 mm.
    pub fn new(ice: IceKind, sensor: SensorKind, geometry: Geometry) -> Self {
        SimConfig {
            ice,
            sensor,
            geometry,
            max_mm: 15.0,
            step_mm: 0.1,
            params: ice.params(),
            coupling: Coupling::ThesisLiteral,
            fibre_spread: true,
            fibre_seed: DEFAULT_FIBRE_SEED,
            diffuse_fresnel: DiffuseFresnel::Facet,
        }
    }

    /// Check the numbers; `Err` with a message for the user.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.step_mm.is_finite() && self.step_mm > 0.0) {
            return Err(SimError::BadParam(format!(
                "step must be a positive number of mm, got {}",
                self.step_mm
            )));
        }
        if !(self.max_mm.is_finite() && self.max_mm >= 0.0 && self.max_mm <= MAX_THICKNESS_MM) {
            return Err(SimError::BadParam(format!(
                "max thickness must be in 0..={MAX_THICKNESS_MM} mm, got {}",
                self.max_mm
            )));
        }
        if self.max_mm / self.step_mm > 100_000.0 {
            return Err(SimError::BadParam(
                "too many thickness steps (> 100000)".into(),
            ));
        }
        let p = &self.params;
        if !(0.0..=1.0).contains(&p.p_bubble) {
            return Err(SimError::BadParam(
                "bubble probability must be in 0..=1".into(),
            ));
        }
        if !(p.n_medium.is_finite() && p.n_medium > 1.0) {
            return Err(SimError::BadParam("refractive index must be > 1".into()));
        }
        let lim = 20f64.to_radians();
        if !(0.0..=lim).contains(&p.slope_max_rad) {
            return Err(SimError::BadParam(
                "surface slope must be in 0..=20°".into(),
            ));
        }
        if !(0.0..=(60f64.to_radians())).contains(&p.diffuse_max_rad) {
            return Err(SimError::BadParam(
                "diffuse angle must be in 0..=60°".into(),
            ));
        }
        Ok(())
    }

    /// The output thicknesses 0, step, 2·step, … ≤ max_mm.
    pub fn thicknesses_mm(&self) -> Vec<f64> {
        self.thickness_grid_mm(0)
    }

    /// [`SimConfig::thicknesses_mm`] continued on their grid by `extra` more.
    pub(crate) fn thickness_grid_mm(&self, extra: usize) -> Vec<f64> {
        let n = (self.max_mm / self.step_mm + 1e-9).floor() as usize;
        (0..=n + extra).map(|i| i as f64 * self.step_mm).collect()
    }
}

/// Errors of the simulator.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SimError {
    /// A parameter is out of range.
    #[error("bad parameter: {0}")]
    BadParam(String),
}
