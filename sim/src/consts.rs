//! Physical constants and model constants: one source of truth each.

/// Refractive index of the fibre core (thesis §3.1.1).
pub const N_FIBRE: f64 = 1.581;
/// Refractive index of the fibre cladding (a project value: the thesis uses NA directly).
pub const N_CLAD: f64 = 1.487;
/// Numerical aperture of the fibres (thesis §3.2.2, eq. 3.17).
pub const NA: f64 = 0.55;
/// Refractive index of ice (thesis §3.1.1).
pub const N_ICE: f64 = 1.31;
/// Refractive index of water (thesis §5.2.3).
pub const N_WATER: f64 = 1.33;
/// Refractive index of air (thesis §3.1, IV).
pub const N_AIR: f64 = 1.00028;
/// Absorption coefficient of ice at 940 nm, 12 m⁻¹ (thesis §3.3), in mm⁻¹. Used for water too.
pub const ALPHA_PER_MM: f64 = 12.0e-3;
/// Total flux of the source bundle, W (thesis §3.3: Φ_ray = 5 mW / N).
pub const SOURCE_FLUX_W: f64 = 5.0e-3;
/// Inclination of the fibre axes toward +x, degrees (thesis §3.2, eq. 3.20).
pub const INCLINATION_DEG: f64 = 30.0;
/// Fraction of a ray's flux that goes on unchanged at a bubble (thesis §3.2.2, Fig. 3.11).
pub const FORWARD_FRACTION: f64 = 0.95;
/// Thickness of one ice layer of the bubble discretisation Δ_Ice, mm (thesis §3.2.3).
pub const BUBBLE_LAYER_MM: f64 = 0.1;
/// Largest thickness the simulator accepts, mm.
pub const MAX_THICKNESS_MM: f64 = 100.0;
/// Responsivity of the phototransistors, A/W (flux on a bundle to current). Chosen so the
/// simulated mean rime I1 at 15 mm is ≈ 30 µA like the thesis (Fig. 5.7, 5.16); see README.
pub const RESPONSIVITY_A_PER_W: f64 = 0.079;
/// Sensor A: fractions of the flux reflected at the fibre face that leak into bundle 1 and
/// bundle 2 through the transparent separation; chosen to give the dry offsets of thesis
/// §5.2.1 (I1 ≈ 13 µA, I2 ≈ 2.5 µA).
pub const SENSOR_A_LEAK: [f64; 2] = [0.27, 0.052];
/// Default seed of the fibre angles (the sensor as built).
pub const DEFAULT_FIBRE_SEED: u64 = 0xF015_5EED;
