#![doc = include_str!("../README.md")]
//!
//! ## Modules
//!
//! - [`laws`]: Snell, Fresnel, Beer–Lambert, fibre acceptance (thesis §3.1).
//! - [`config`]: the configuration ([`SimConfig`], [`IceKind`], …); [`curve`]: the output ([`Curve`]).
//! - [`model`]: the sensor and its ray tracer (the phases of one accretion in `tracer.rs`); [`accretion_curve`] gives one physical accretion, currents I1(d), I2(d) in µA.
//! - [`analytic`]: the conventional overlap model (thesis §2.1, §3.3).
//! - [`montecarlo`]: mean μ(d), covariance Σ(d), fits and the Cramér–Rao bound (§5.4).
//! - [`gain`]: the same bound with the gain an unknown nuisance parameter.
//! - [`streams`]: the random-stream layout: every draw's stream, keyed by (seed, run).
//! - [`geometry`], [`consts`]: the sensor face, every constant once.
//! - [`table`]: the node estimator's response table (μ, Σ per medium, fixed point, Rust source).

pub mod analytic;
mod bubbles;
pub mod config;
pub mod consts;
pub mod curve;
mod diffuse;
pub mod gain;
pub mod geometry;
mod kernels;
pub mod laws;
pub mod model;
pub mod montecarlo;
mod pack;
mod setup;
mod specular;
pub mod streams;
pub mod table;
mod tracer;
mod walk;

pub use analytic::analytic_curve;
pub use geometry::{Geometry, Region};
pub use kernels::{Isa, isa, with_isa};
pub use model::{
    Coupling, Curve, CurvePoint, DiffuseFresnel, IceKind, IceParams, SensorKind, SensorModel,
    SimConfig, SimError, accretion_curve,
};
pub use montecarlo::{CrlbPoint, McPoint, MonteCarlo, crlb, monte_carlo};
