//! Virtual hardware for the firmware's own `Node`: a virtual clock, output
//! pins, an environment model (ice, light, air temperature over time), the
//! analog front end and a simulated ADC implementing
//! [`fois_firmware::PhotoAdc`]; and the virtual node, the firmware's own
//! `Node` on them in virtual time. `foisctl virtual-node` / `foisctl demo`
//! and the hardware-in-loop suite in `hil/` build on it.
//!
//! ```
//! use std::sync::Arc;
//! use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};
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
pub mod node;
pub mod scenario;

pub use adc::SimAdc;
pub use clock::{VirtualClock, VirtualDelay, VirtualPin};
pub use environment::{Cover, Environment, Segment, Timeline, Truth};
pub use frontend::FrontEnd;
pub use node::{FirmwareNode, NodeOptions, SharedStorage, VirtualNode};
pub use scenario::Scenario;
