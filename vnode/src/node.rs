//! The virtual node: the firmware's own [`Node`] on virtual hardware, in
//! virtual time. (`foisctl` serves it on a pseudo-terminal.)
//!
//! The runner does what the board's main loop does, with the board's own
//! code: the firmware's [`Schedule`] decides when `Hello` goes out and when
//! a frame runs (the first poll at boot sends `Hello` and runs the first
//! frame; a new stream period applies at once), a pending save runs when it
//! comes due, host bytes go to `handle_rx`, and a `Reset` boots a fresh
//! `Node` and a fresh `Schedule` on the same flash. The flash is the
//! board's too: the firmware's [`FlashStore`] (sequential-storage) over a
//! [`VirtualFlash`] (the firmware's `RamFlash` of the board's geometry, two
//! 16 KiB sectors, whose erases stall the virtual clock as the board's do).
//!
//! Updates: the node holds the firmware's updater over the board's boot
//! state and DFU slot in RAM (`crate::update_slots`); a reset runs
//! embassy-boot's bootloader on them first, and the fresh `Node` runs the
//! version the active slot's image carries (on trial after a swap, so it
//! confirms itself after its self-test, as the board's image does).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};

use fois_firmware::estimator::EstimatorParams;
use fois_firmware::platform::schedule::Schedule;
use fois_firmware::update::UpdateKey;
use fois_firmware::{BoardInfo, MemStorage, Node};
use fois_protocol::ResetReason;

pub use crate::shared_storage::SharedStorage;
pub use crate::shared_storage::factory_record;
use crate::update_slots::{UpdatePartitions, VirtualUpdater};
use crate::{Environment, SimAdc, Truth, VirtualClock, VirtualDelay, VirtualPin};

/// The firmware node on virtual hardware.
pub type FirmwareNode =
    Node<SimAdc, VirtualPin, VirtualPin, VirtualPin, VirtualDelay, SharedStorage, VirtualUpdater>;

/// How to build a virtual node.
#[derive(Debug, Clone)]
pub struct NodeOptions {
    /// Seed of the ADC noise.
    pub seed: u64,
    /// Board name in `Hello`.
    pub board: &'static str,
    /// Initial record (config + baseline), written to the erased flash
    /// before boot; empty = a first boot (defaults).
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
    /// The MCU unique id the node reports in `Hello`. `None`: an id of its
    /// own, distinct for every node built in any running process
    /// ([`instance_unique_id`]), as every board has its own; a gateway
    /// names entities after it, so two virtual nodes must not share one.
    pub unique_id: Option<[u8; 12]>,
    /// A factory calibration of the optical gain, (gain, relative sd),
    /// e.g. `(1.0, 0.02)`: written into the flash before the node boots,
    /// if the flash holds no record ([`factory_record`]), as a calibration
    /// against a target (`Command::CalibrateGain`) would have left it. The
    /// node then starts with that gain as its prior instead of an unknown
    /// one. `None`: a new node, its gain unknown (the default).
    pub gain_calibration: Option<(f64, f64)>,
    /// The config in the flash before the node's first boot (a scenario's
    /// `[config]`), written with the gain calibration if the flash holds no
    /// record; `None`: the defaults.
    pub config: Option<fois_protocol::Config>,
    /// The key update images are checked with (the firmware's built-in
    /// public key on a board); [`UpdateKey::NONE`]: every image refused.
    pub update_key: UpdateKey,
}

/// A unique id no other virtual node has while this process runs (nor
/// another process: `FV`, the process id, a count of the nodes built here).
pub fn instance_unique_id() -> [u8; 12] {
    static BUILT: AtomicU32 = AtomicU32::new(0);
    let n = BUILT.fetch_add(1, Ordering::Relaxed);
    let mut id = [0u8; 12];
    id[..2].copy_from_slice(b"FV");
    id[2..6].copy_from_slice(&std::process::id().to_be_bytes());
    id[8..].copy_from_slice(&n.to_be_bytes());
    id
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
            unique_id: None,
            gain_calibration: None,
            config: None,
            update_key: UpdateKey::NONE,
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
    schedule: Schedule,
    resets: u32,
    frames: u64,
    storage: SharedStorage,
    partitions: UpdatePartitions,
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
        partitions: &UpdatePartitions,
    ) -> FirmwareNode {
        let adc = SimAdc::new(
            self.clock.clone(),
            self.led.clone(),
            self.env.clone(),
            opts.seed.wrapping_add(u64::from(resets)),
        );
        let mut info = BoardInfo::simulated(opts.board);
        info.reset_reason = reason;
        info.unique_id = opts.unique_id.unwrap_or(*b"FOIS-VIRTUAL");
        let mut node = Node::new_with_updates(
            adc,
            self.led.clone(),
            self.alarm.clone(),
            self.indicator.clone(),
            VirtualDelay::new(self.clock.clone()),
            storage,
            info,
            partitions.updater(opts.update_key),
        );
        node.set_estimator_params(opts.estimator);
        node
    }
}

impl VirtualNode {
    /// Build a node at virtual time 0 in `env`.
    pub fn new(env: Arc<Environment>, mut opts: NodeOptions) -> Self {
        // One id for the node's whole life, resets included.
        opts.unique_id.get_or_insert_with(instance_unique_id);
        let clock = VirtualClock::new();
        let led = VirtualPin::with_clock(clock.clone());
        let alarm = VirtualPin::with_clock(clock.clone());
        let indicator = VirtualPin::with_clock(clock.clone());
        let storage = match &opts.state_file {
            Some(p) => SharedStorage::with_file(p).unwrap_or_else(|_| {
                // Unreadable state (the CLI refuses it before this): erased
                // flash; saves try to rewrite the file.
                SharedStorage::erased_with_file(p)
            }),
            None => SharedStorage::new(opts.storage.clone()),
        };
        if opts.gain_calibration.is_some() || opts.config.is_some() {
            let mut record = match opts.gain_calibration {
                Some((gain, rel_sd)) => factory_record(gain, rel_sd),
                None => fois_firmware::storage::record::Record {
                    config: fois_protocol::Config::default(),
                    baseline: None,
                    gain: None,
                    gain_calibration: None,
                    link: fois_protocol::LinkSettings::default(),
                },
            };
            if let Some(c) = &opts.config {
                record.config = c.clone();
            }
            storage.write_if_empty(&record);
        }
        storage.stall_on(&clock);
        let partitions = UpdatePartitions::erased();
        partitions.stall_on(&clock);
        let hw = Hardware {
            clock: &clock,
            led: &led,
            alarm: &alarm,
            indicator: &indicator,
            env: &env,
        };
        let node = hw.node(&opts, 0, ResetReason::PowerOn, storage.clone(), &partitions);
        VirtualNode {
            node,
            clock,
            led,
            alarm,
            indicator,
            env,
            opts,
            schedule: Schedule::new(),
            resets: 0,
            frames: 0,
            storage,
            partitions,
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

    /// The node's flash store (shared with the node).
    pub fn shared_storage(&self) -> &SharedStorage {
        &self.storage
    }

    /// The update partitions (boot state, active and DFU slots).
    pub fn update_partitions(&self) -> &UpdatePartitions {
        &self.partitions
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

    /// Virtual time of the next frame, ns (now, before the first poll).
    pub fn next_frame_ns(&self) -> u64 {
        if self.schedule == Schedule::new() {
            return self.clock.now_ns();
        }
        self.schedule.next_wake_ms(true).saturating_mul(NS_PER_MS)
    }

    /// The schedule the node runs on (the board's: `fois_firmware::platform::schedule`).
    pub fn schedule(&self) -> &Schedule {
        &self.schedule
    }

    /// The earliest virtual time something is due (frame, `Hello` or a
    /// pending save), ns; now before the first poll (boot).
    pub fn next_due_ns(&self) -> u64 {
        if self.schedule == Schedule::new() {
            return self.clock.now_ns();
        }
        let streaming = self.node.is_streaming();
        let mut wake_ms = self.schedule.next_wake_ms(streaming);
        if let Some(save_ms) = self.node.save_due_ms() {
            wake_ms = wake_ms.min(save_ms);
        }
        wake_ms.saturating_mul(NS_PER_MS)
    }

    /// Bytes from the host. As the board's link task: one host frame (up to
    /// its 0x00) at a time, and after each the main loop runs what came due
    /// (a frame, a save), so a host flooding commands (a dark calibration
    /// takes up to 2 s) cannot starve the measurement.
    pub fn handle_rx(&mut self, bytes: &[u8], tx: &mut impl FnMut(&[u8])) {
        for piece in bytes.split_inclusive(|b| *b == 0) {
            let now = self.clock.now_ms();
            self.node_mut().handle_rx(piece, now, tx);
            self.after_commands(tx);
        }
    }

    /// Carry out one command as the host link would (its answer is not
    /// sent), then run what came due (a reset it asked for included).
    pub fn command(
        &mut self,
        cmd: fois_protocol::Command,
        tx: &mut impl FnMut(&[u8]),
    ) -> Result<fois_protocol::AckResult, fois_protocol::ErrorCode> {
        let now = self.clock.now_ms();
        let r = self.node_mut().command(cmd, now);
        self.after_commands(tx);
        r
    }

    /// Carry out a Modbus write's action (after its answer went out), as
    /// the board's main loop does, then run what came due (a reset the
    /// action asked for included). Returns the `last_result` register's
    /// value.
    pub fn modbus_action(
        &mut self,
        action: fois_firmware::modbus::Action,
        tx: &mut impl FnMut(&[u8]),
    ) -> fois_protocol::registers::CommandResult {
        let now = self.clock.now_ms();
        let r = self.node_mut().modbus_action(action, now);
        self.after_commands(tx);
        r
    }

    /// The user button (then the main loop polls again, as on the board).
    pub fn press_button(&mut self, tx: &mut impl FnMut(&[u8])) {
        let now = self.clock.now_ms();
        self.node_mut().button_pressed(now, tx);
        self.poll(tx);
    }

    fn after_commands(&mut self, tx: &mut impl FnMut(&[u8])) {
        self.reset_if_asked();
        // The board's link task wakes the main loop after every command
        // (a new period, a StopStream's Hello, a Reset apply from now).
        self.poll(tx);
    }

    /// A reset the node asked for (a `Reset` or a commit acknowledged, a
    /// trial past its deadline after a frame): the boot stage, then a
    /// fresh node and schedule.
    fn reset_if_asked(&mut self) {
        if self.node_mut().take_reset_request() {
            // A fresh node on the same (shared) storage, as after a reset.
            self.resets += 1;
            // The chip's reset puts every GPIO back to its reset state at
            // once: LED, alarm output and LD2 are off before the new node
            // runs its first frame.
            for pin in [&mut self.led, &mut self.alarm, &mut self.indicator] {
                let Ok(()) = embedded_hal::digital::OutputPin::set_low(pin);
            }
            // The boot stage: a committed image swapped in, or a trial
            // that was not confirmed swapped out (the RAM flash cannot
            // fail; the board would reset and resume).
            let _ = self.partitions.run_bootloader();
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
                &self.partitions,
            );
            // The board reboots: a fresh schedule, whose first poll sends
            // Hello and runs the first frame.
            self.schedule = Schedule::new();
        }
    }

    /// One pass of the board's main loop at the current virtual time: what
    /// the schedule says is due, else a pending save that came due.
    fn poll(&mut self, tx: &mut impl FnMut(&[u8])) {
        let now_ms = self.clock.now_ms();
        let streaming = self.node.is_streaming();
        let period_ms = self.node.frame_period_ms();
        let due = self.schedule.poll(now_ms, streaming, period_ms);
        if due.hello {
            self.node.send_hello(tx);
        }
        if due.frame {
            // Runs the pending save too, after the frame.
            self.run_one_frame(tx);
            // A trial past its deadline asks for the reset that rolls back.
            self.reset_if_asked();
        } else {
            self.node.poll_storage(now_ms);
        }
    }

    /// Run everything due up to virtual time `t_ns` (frames, hellos, saves,
    /// the boot-time calibration); the clock ends at `t_ns` or later.
    pub fn advance_to(&mut self, t_ns: u64, tx: &mut impl FnMut(&[u8])) {
        loop {
            let due = self.next_due_ns();
            if due > t_ns {
                break;
            }
            self.clock.advance_to_ns(due);
            self.poll(tx);
        }
        self.clock.advance_to_ns(t_ns);
    }

    fn run_one_frame(&mut self, tx: &mut impl FnMut(&[u8])) {
        let start = self.clock.now_ns();
        if let Some(at) = self.opts.calibrate_at_s {
            let at_ns = (at * 1e9) as u64;
            if start >= at_ns && self.truth().cover == crate::Cover::Dry {
                self.opts.calibrate_at_s = None;
                let now = self.clock.now_ms();
                self.node.button_pressed(now, tx);
            } else if start >= at_ns {
                self.opts.calibrate_at_s = None;
            }
        }
        let now_ms = self.clock.now_ms();
        self.node_mut().run_frame(now_ms, tx);
        self.frames += 1;
    }

    /// Run until virtual time `t_s`.
    pub fn run_until_s(&mut self, t_s: f64, tx: &mut impl FnMut(&[u8])) {
        self.advance_to((t_s * 1e9) as u64, tx);
    }

    /// Run exactly one more frame (jumping the clock to it; `Hello`s and
    /// saves due before it happen on the way).
    pub fn step_frame(&mut self, tx: &mut impl FnMut(&[u8])) {
        let before = self.frames;
        while self.frames == before {
            let t = self.next_due_ns();
            self.advance_to(t, tx);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::{Cover, Segment, Timeline};
    use fois_firmware::Storage;
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

    #[test]
    fn every_virtual_node_has_its_own_unique_id_for_its_whole_life() {
        let env = || {
            Arc::new(Environment::new(
                Timeline::new(vec![Segment::new(60.0, Cover::Dry)]),
                fois_sim::SensorKind::B,
                1,
            ))
        };
        let mut a = VirtualNode::new(env(), NodeOptions::default());
        let b = VirtualNode::new(env(), NodeOptions::default());
        let id_a = a.node().hello().unique_id;
        assert_ne!(id_a, b.node().hello().unique_id);
        assert_eq!(&id_a[..2], b"FV");
        assert_eq!(id_a[2..6], std::process::id().to_be_bytes());
        // A reset keeps it (the board's id is in silicon).
        let reset = encode_to_vec(&HostFrame {
            id: 1,
            cmd: Command::Reset,
        });
        a.run_until_s(2.0, &mut |_: &[u8]| {});
        a.handle_rx(&reset, &mut |_: &[u8]| {});
        a.run_until_s(4.0, &mut |_: &[u8]| {});
        assert_eq!(a.resets(), 1);
        assert_eq!(a.node().hello().unique_id, id_a);
        // A fixed id is used as given.
        let fixed = VirtualNode::new(
            env(),
            NodeOptions {
                unique_id: Some(*b"FOIS-VIRTUAL"),
                ..NodeOptions::default()
            },
        );
        assert_eq!(&fixed.node().hello().unique_id, b"FOIS-VIRTUAL");
    }

    /// The gain the node's first `MeasurementV5` reports.
    fn first_gain(opts: NodeOptions) -> (f64, f64) {
        use fois_protocol::{DeviceFrame, DeviceMsg, FrameDecoder};
        let env = Arc::new(Environment::new(
            Timeline::new(vec![Segment::new(60.0, Cover::Dry)]),
            fois_sim::SensorKind::B,
            1,
        ));
        let mut vn = VirtualNode::new(env, opts);
        let mut dec = FrameDecoder::<{ fois_protocol::MAX_FRAME }>::new();
        let mut gain = None;
        while gain.is_none() {
            vn.step_frame(&mut |bytes: &[u8]| {
                dec.feed::<DeviceFrame>(bytes, |r| {
                    if let DeviceMsg::MeasurementV5(m) = r.unwrap().msg {
                        let g = m.gain.unwrap();
                        gain.get_or_insert((g.gain(), g.sigma()));
                    }
                })
            });
        }
        gain.unwrap()
    }

    #[test]
    fn a_factory_calibrated_node_starts_with_its_calibrated_gain() {
        let calibrated = NodeOptions {
            calibrate_at_s: None,
            gain_calibration: Some((1.0, 0.02)),
            ..NodeOptions::default()
        };
        let (g, sd) = first_gain(calibrated);
        assert!((g - 1.0).abs() < 0.005, "gain {g}");
        assert!((sd - 0.02).abs() < 0.002, "sd {sd}");
        let (g, sd) = first_gain(NodeOptions {
            calibrate_at_s: None,
            gain_calibration: Some((0.8, 0.05)),
            ..NodeOptions::default()
        });
        assert!((g - 0.8).abs() < 0.005, "gain {g}");
        assert!((sd - 0.04).abs() < 0.004, "sd {sd}");
        // A new node: the gain unknown (prior 1 ± 30 %).
        let (_, sd) = first_gain(NodeOptions {
            calibrate_at_s: None,
            ..NodeOptions::default()
        });
        assert!(sd > 0.2, "sd {sd}");
    }

    #[test]
    fn a_factory_calibration_leaves_a_stored_record_alone() {
        let record = factory_record(0.9, 0.02);
        let mut out = [0u8; fois_firmware::storage::record::MAX_RECORD];
        let n = fois_firmware::storage::record::encode(&record, &mut out);
        let storage = SharedStorage::new(MemStorage::with_bytes(&out[..n]));
        assert!(!storage.write_if_empty(&factory_record(1.0, 0.02)));
        let mut buf = [0u8; fois_firmware::storage::record::MAX_RECORD];
        let n = storage.snapshot().read(&mut buf).unwrap();
        assert_eq!(
            fois_firmware::storage::record::decode(&buf[..n]).unwrap(),
            record
        );
        let erased = SharedStorage::new(MemStorage::new());
        assert!(erased.write_if_empty(&record));
        let n = erased.snapshot().read(&mut buf).unwrap();
        assert_eq!(
            fois_firmware::storage::record::decode(&buf[..n]).unwrap(),
            record
        );
    }
}
