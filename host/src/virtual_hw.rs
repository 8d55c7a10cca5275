//! Virtual hardware for the firmware's own `Node`: a virtual clock, output
//! pins, an environment model (ice, light, air temperature over time), the
//! analog front end and a simulated ADC implementing
//! [`fois_firmware::PhotoAdc`]. The virtual node (`foisctl virtual-node`,
//! `foisctl demo`) and the hardware-in-loop suite in `hil/` build on it.
//!
//! ```
//! use std::sync::Arc;
//! use fois_host::virtual_hw::{Cover, Environment, Segment, Timeline};
//! use fois_host::virtual_node::{NodeOptions, VirtualNode};
//!
//! let timeline = Timeline::new(vec![
//!     Segment::new(60.0, Cover::Dry).temp(-5.0),
//!     Segment::new(600.0, Cover::Rime).rate(6.0).temp(-5.0).ambient([20.0, 10.0]),
//! ]);
//! let env = Arc::new(Environment::new(timeline, fois_sim::SensorKind::B, 1));
//! let mut node = VirtualNode::new(env, NodeOptions::default());
//! let mut frames = Vec::new();
//! node.run_until_s(120.0, &mut |b: &[u8]| frames.extend_from_slice(b));
//! assert!(node.alarm_on());
//! ```

pub mod adc;
pub mod clock;
pub mod environment;
pub mod frontend;
pub mod scenario;

pub use adc::SimAdc;
pub use clock::{VirtualClock, VirtualDelay, VirtualPin};
pub use environment::{Cover, Environment, Segment, Timeline, Truth};
pub use frontend::FrontEnd;
pub use scenario::Scenario;
