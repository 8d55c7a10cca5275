//! The virtual node: the firmware's own [`Node`] on virtual hardware, in
//! virtual time. (`foisctl` serves it on a pseudo-terminal.)
//!
//! The runner does what the board's main loop does: a `Hello` at boot and
//! every second until streaming starts, one frame every frame period, host
//! bytes to `handle_rx`, and a fresh `Node` (same storage) after a `Reset`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use std::sync::Mutex;

use fois_firmware::estimator::EstimatorParams;
use fois_firmware::{BoardInfo, MemStorage, Node, Storage, StorageError};
use fois_protocol::ResetReason;

use crate::{Environment, SimAdc, Truth, VirtualClock, VirtualDelay, VirtualPin};

/// The firmware node on virtual hardware.
pub type FirmwareNode =
    Node<SimAdc, VirtualPin, VirtualPin, VirtualPin, VirtualDelay, SharedStorage>;

/// The node's flash record: RAM shared with the runner (so it survives a
/// `Reset` and can be inspected), optionally mirrored to a file (so it
/// survives the process, like flash survives a power cycle).
#[derive(Debug, Clone)]
pub struct SharedStorage {
    mem: Arc<Mutex<MemStorage>>,
    file: Option<PathBuf>,
}

impl SharedStorage {
    /// RAM only, starting with `initial`.
    pub fn new(initial: MemStorage) -> Self {
        SharedStorage {
            mem: Arc::new(Mutex::new(initial)),
            file: None,
        }
    }

    /// Backed by `path`: starts with its bytes (empty if it does not exist)
    /// and rewrites it on every write.
    pub fn with_file(path: &Path) -> std::io::Result<Self> {
        let initial = match std::fs::read(path) {
            Ok(bytes) => MemStorage::with_bytes(&bytes),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => MemStorage::new(),
            Err(e) => return Err(e),
        };
        Ok(SharedStorage {
            mem: Arc::new(Mutex::new(initial)),
            file: Some(path.to_path_buf()),
        })
    }

    /// A copy of the record now.
    pub fn snapshot(&self) -> MemStorage {
        self.mem.lock().map(|m| m.clone()).unwrap_or_default()
    }
}

impl Storage for SharedStorage {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, StorageError> {
        self.mem.lock().map_err(|_| StorageError::Read)?.read(buf)
    }

    fn write(&mut self, data: &[u8]) -> Result<(), StorageError> {
        let mut mem = self.mem.lock().map_err(|_| StorageError::Write)?;
        mem.write(data)?;
        if let Some(path) = &self.file {
            std::fs::write(path, mem.bytes()).map_err(|_| StorageError::Write)?;
        }
        Ok(())
    }
}

/// How to build a virtual node.
#[derive(Debug, Clone)]
pub struct NodeOptions {
    /// Seed of the ADC noise.
    pub seed: u64,
    /// Board name in `Hello`.
    pub board: &'static str,
    /// Initial storage (config + baseline record); empty = defaults.
    pub storage: MemStorage,
    /// Keep the storage in this file instead (loaded if it exists, rewritten
    /// on every write; `storage` is then ignored).
    pub state_file: Option<PathBuf>,
    /// Press the user button (dark calibration) at this virtual time, s,
    /// if the face is dry then. `None`: never.
    pub calibrate_at_s: Option<f64>,
    /// The ice estimator's settings (library settings, not in the protocol
    /// `Config`: defaults and meaning in firmware/README.md, "The ice
    /// estimator"). Passed to every `Node` this runner builds, after each
    /// reset too, as the board passes its own.
    pub estimator: EstimatorParams,
}

impl Default for NodeOptions {
    fn default() -> Self {
        NodeOptions {
            seed: 1,
            board: "virtual-f446",
            storage: MemStorage::new(),
            state_file: None,
            calibrate_at_s: Some(1.0),
            estimator: EstimatorParams::default(),
        }
    }
}

/// A node + its virtual hardware.
pub struct VirtualNode {
    node: FirmwareNode,
    clock: VirtualClock,
    led: VirtualPin,
    alarm: VirtualPin,
    indicator: VirtualPin,
    env: Arc<Environment>,
    opts: NodeOptions,
    next_frame_ns: u64,
    next_hello_ns: u64,
    booted: bool,
    resets: u32,
    frames: u64,
    storage: SharedStorage,
}

const NS_PER_MS: u64 = 1_000_000;

/// The virtual hardware a node is built on.
struct Hardware<'a> {
    clock: &'a VirtualClock,
    led: &'a VirtualPin,
    alarm: &'a VirtualPin,
    indicator: &'a VirtualPin,
    env: &'a Arc<Environment>,
}

impl Hardware<'_> {
    /// The firmware node on this hardware after its `resets`-th reset (the
    /// ADC noise stream differs per boot).
    fn node(
        &self,
        opts: &NodeOptions,
        resets: u32,
        reason: ResetReason,
        storage: SharedStorage,
    ) -> FirmwareNode {
        let adc = SimAdc::new(
            self.clock.clone(),
            self.led.clone(),
            self.env.clone(),
            opts.seed.wrapping_add(u64::from(resets)),
        );
        let mut info = BoardInfo::simulated(opts.board);
        info.reset_reason = reason;
        info.unique_id = *b"FOIS-VIRTUAL";
        let mut node = Node::new(
            adc,
            self.led.clone(),
            self.alarm.clone(),
            self.indicator.clone(),
            VirtualDelay::new(self.clock.clone()),
            storage,
            info,
        );
        node.set_estimator_params(opts.estimator);
        node
    }
}

impl VirtualNode {
    /// Build a node at virtual time 0 in `env`.
    pub fn new(env: Arc<Environment>, opts: NodeOptions) -> Self {
        let clock = VirtualClock::new();
        let led = VirtualPin::with_clock(clock.clone());
        let alarm = VirtualPin::with_clock(clock.clone());
        let indicator = VirtualPin::with_clock(clock.clone());
        let storage = match &opts.state_file {
            Some(p) => SharedStorage::with_file(p).unwrap_or_else(|_| {
                // Unreadable state: start empty, writes will report failure.
                SharedStorage {
                    mem: Arc::new(Mutex::new(MemStorage::new())),
                    file: Some(p.clone()),
                }
            }),
            None => SharedStorage::new(opts.storage.clone()),
        };
        let hw = Hardware {
            clock: &clock,
            led: &led,
            alarm: &alarm,
            indicator: &indicator,
            env: &env,
        };
        let node = hw.node(&opts, 0, ResetReason::PowerOn, storage.clone());
        VirtualNode {
            node,
            clock,
            led,
            alarm,
            indicator,
            env,
            opts,
            next_frame_ns: 0,
            next_hello_ns: 0,
            booted: false,
            resets: 0,
            frames: 0,
            storage,
        }
    }

    fn node_mut(&mut self) -> &mut FirmwareNode {
        &mut self.node
    }

    /// The firmware node.
    pub fn node(&self) -> &FirmwareNode {
        &self.node
    }

    /// Shared virtual clock.
    pub fn clock(&self) -> &VirtualClock {
        &self.clock
    }

    /// The environment.
    pub fn env(&self) -> &Arc<Environment> {
        &self.env
    }

    /// The conditions now.
    pub fn truth(&self) -> Truth {
        self.env.truth(self.clock.now_ns())
    }

    /// Alarm output (PA9) level.
    pub fn alarm_on(&self) -> bool {
        self.alarm.is_high()
    }

    /// The alarm pin (edges with virtual times).
    pub fn alarm_pin(&self) -> &VirtualPin {
        &self.alarm
    }

    /// The indicator pin (LD2).
    pub fn indicator_pin(&self) -> &VirtualPin {
        &self.indicator
    }

    /// The LED pin.
    pub fn led_pin(&self) -> &VirtualPin {
        &self.led
    }

    /// The node's persisted record now (config + baseline).
    pub fn storage(&self) -> MemStorage {
        self.storage.snapshot()
    }

    /// Frames run so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Resets carried out (the `Reset` command).
    pub fn resets(&self) -> u32 {
        self.resets
    }

    /// Virtual time of the next frame, ns.
    pub fn next_frame_ns(&self) -> u64 {
        self.next_frame_ns
    }

    /// The earliest virtual time something is due (frame or hello), ns.
    pub fn next_due_ns(&self) -> u64 {
        if !self.booted {
            return self.clock.now_ns();
        }
        if self.node().is_streaming() {
            self.next_frame_ns
        } else {
            self.next_frame_ns.min(self.next_hello_ns)
        }
    }

    /// Bytes from the host.
    pub fn handle_rx(&mut self, bytes: &[u8], tx: &mut impl FnMut(&[u8])) {
        let now = self.clock.now_ms();
        self.node_mut().handle_rx(bytes, now, tx);
        self.after_commands(tx);
    }

    /// The user button.
    pub fn press_button(&mut self, tx: &mut impl FnMut(&[u8])) {
        let now = self.clock.now_ms();
        self.node_mut().button_pressed(now, tx);
    }

    fn after_commands(&mut self, tx: &mut impl FnMut(&[u8])) {
        if self.node_mut().take_reset_request() {
            // A fresh node on the same (shared) storage, as after a reset.
            self.resets += 1;
            let hw = Hardware {
                clock: &self.clock,
                led: &self.led,
                alarm: &self.alarm,
                indicator: &self.indicator,
                env: &self.env,
            };
            self.node = hw.node(
                &self.opts,
                self.resets,
                ResetReason::Software,
                self.storage.clone(),
            );
            self.booted = false;
            self.boot(tx);
        }
    }

    fn boot(&mut self, tx: &mut impl FnMut(&[u8])) {
        self.booted = true;
        let now = self.clock.now_ns();
        self.node_mut().send_hello(tx);
        self.next_hello_ns = now + 1_000 * NS_PER_MS;
        self.next_frame_ns = now + u64::from(self.node().frame_period_ms()) * NS_PER_MS;
    }

    /// Run everything due up to virtual time `t_ns` (frames, hellos, the
    /// boot-time calibration); the clock ends at `t_ns` or later.
    pub fn advance_to(&mut self, t_ns: u64, tx: &mut impl FnMut(&[u8])) {
        if !self.booted {
            self.boot(tx);
        }
        loop {
            let due = self.next_due_ns();
            if due > t_ns {
                break;
            }
            self.clock.advance_to_ns(due);
            if !self.node().is_streaming() && self.next_hello_ns <= due {
                self.node_mut().send_hello(tx);
                self.next_hello_ns = due + 1_000 * NS_PER_MS;
            }
            if self.next_frame_ns <= due {
                self.run_one_frame(tx);
            }
        }
        self.clock.advance_to_ns(t_ns);
    }

    fn run_one_frame(&mut self, tx: &mut impl FnMut(&[u8])) {
        let start = self.clock.now_ns();
        if let Some(at) = self.opts.calibrate_at_s {
            let at_ns = (at * 1e9) as u64;
            if start >= at_ns && self.truth().cover == crate::Cover::Dry {
                self.opts.calibrate_at_s = None;
                self.press_button(tx);
            } else if start >= at_ns {
                self.opts.calibrate_at_s = None;
            }
        }
        let now_ms = self.clock.now_ms();
        self.node_mut().run_frame(now_ms, tx);
        self.frames += 1;
        let period = u64::from(self.node().frame_period_ms().max(1)) * NS_PER_MS;
        // Frames start on a fixed grid (as the board's ticker does).
        self.next_frame_ns = self.next_frame_ns.max(start) + period;
        if self.next_frame_ns <= self.clock.now_ns() {
            self.next_frame_ns = self.clock.now_ns() + period;
        }
    }

    /// Run until virtual time `t_s`.
    pub fn run_until_s(&mut self, t_s: f64, tx: &mut impl FnMut(&[u8])) {
        self.advance_to((t_s * 1e9) as u64, tx);
    }

    /// Run exactly one more frame (jumping the clock to it).
    pub fn step_frame(&mut self, tx: &mut impl FnMut(&[u8])) {
        if !self.booted {
            self.boot(tx);
        }
        let t = self.next_frame_ns;
        self.advance_to(t, tx);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::{Cover, Segment, Timeline};
    use fois_protocol::{Command, HostFrame, encode_to_vec};

    #[test]
    fn the_estimator_settings_reach_every_node_it_builds() {
        let env = Arc::new(Environment::new(
            Timeline::new(vec![Segment::new(60.0, Cover::Dry)]),
            fois_sim::SensorKind::B,
            1,
        ));
        let params = EstimatorParams {
            forget_time_s: 5.0,
            max_growth_mm_per_h: 3.0,
            ..EstimatorParams::default()
        };
        assert_ne!(params, EstimatorParams::default());
        let opts = NodeOptions {
            estimator: params,
            ..NodeOptions::default()
        };
        let mut vn = VirtualNode::new(env, opts);
        assert_eq!(*vn.node().estimator().params(), params);
        // After a `Reset` the runner builds a new node: same settings.
        let reset = encode_to_vec(&HostFrame {
            id: 1,
            cmd: Command::Reset,
        });
        vn.run_until_s(2.0, &mut |_: &[u8]| {});
        vn.handle_rx(&reset, &mut |_: &[u8]| {});
        vn.run_until_s(4.0, &mut |_: &[u8]| {});
        assert_eq!(vn.resets(), 1);
        assert_eq!(*vn.node().estimator().params(), params);
    }
}
