//! Virtual nodes for the gateway tests: the firmware's own `Node` on
//! simulated hardware (`fois_vnode`), served on a pseudo-terminal by a
//! thread of the test (`fois_vnode::pty`), exactly as `foisctl
//! virtual-node` serves one. Stopping it closes the pty: the gateway sees
//! its port vanish, as when a USB cable is pulled.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use fois_vnode::pty::{self, LinkGuard, Pty, ServeOptions};
use fois_vnode::{Cover, Environment, NodeOptions, Segment, Timeline, VirtualNode};

/// What a virtual node's face sees, and its pace.
#[derive(Debug, Clone, Copy)]
pub struct Scene {
    /// What forms after the dry start.
    pub cover: Cover,
    /// Accretion rate, mm/h.
    pub rate_mm_per_h: f64,
    /// Air temperature, °C.
    pub temp_c: f64,
    /// Virtual seconds of dry face first.
    pub dry_s: f64,
    /// Seed of the accretion and the ADC noise.
    pub seed: u64,
    /// Virtual seconds per real second.
    pub speed: f64,
}

impl Scene {
    /// A dry face for as long as a test runs, at `speed`.
    pub fn dry(speed: f64, seed: u64) -> Scene {
        Scene {
            cover: Cover::Dry,
            rate_mm_per_h: 0.0,
            temp_c: -5.0,
            dry_s: 1000.0,
            seed,
            speed,
        }
    }

    /// `dry_s` of dry face, then `cover` growing at `rate` mm/h at `temp_c`.
    pub fn film(cover: Cover, rate: f64, temp_c: f64, dry_s: f64, speed: f64, seed: u64) -> Scene {
        Scene {
            cover,
            rate_mm_per_h: rate,
            temp_c,
            dry_s,
            seed,
            speed,
        }
    }

    fn node(&self) -> VirtualNode {
        let segs = vec![
            Segment::new(self.dry_s, Cover::Dry).temp(self.temp_c),
            Segment::new(f64::INFINITY, self.cover)
                .rate(self.rate_mm_per_h)
                .temp(self.temp_c),
        ];
        let env = Arc::new(Environment::new(
            Timeline::new(segs),
            fois_sim::SensorKind::B,
            self.seed,
        ));
        VirtualNode::new(
            env,
            NodeOptions {
                seed: self.seed,
                ..NodeOptions::default()
            },
        )
    }
}

/// A virtual node served on a pty by a thread; stopped (pty closed) on drop.
pub struct NodeProc {
    /// Its pty (/dev/pts/N).
    pub path: String,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    _link: Option<LinkGuard>,
}

impl NodeProc {
    /// Build the node (ray-traces its curves) and serve it.
    pub fn start(scene: Scene) -> NodeProc {
        Self::serve(scene, None)
    }

    /// The same, with a symlink `link` to its pty (a stable name across
    /// restarts).
    pub fn start_linked(scene: Scene, link: &Path) -> NodeProc {
        Self::serve(scene, Some(link))
    }

    fn serve(scene: Scene, link: Option<&Path>) -> NodeProc {
        Self::serve_node(scene.speed, link, move || scene.node())
    }

    /// A node on its own timeline of `segments` (sensor B, ADC noise and
    /// accretion seeded by `seed`) at `speed`.
    pub fn timeline(speed: f64, segments: Vec<Segment>, seed: u64) -> NodeProc {
        Self::start_with(speed, move || {
            let env = Arc::new(Environment::new(
                Timeline::new(segments),
                fois_sim::SensorKind::B,
                seed,
            ));
            VirtualNode::new(
                env,
                NodeOptions {
                    seed,
                    ..NodeOptions::default()
                },
            )
        })
    }

    /// Serve the node `build` makes (on the serving thread: building
    /// ray-traces its curves) at `speed` virtual seconds per real second.
    pub fn start_with(
        speed: f64,
        build: impl FnOnce() -> VirtualNode + Send + 'static,
    ) -> NodeProc {
        Self::serve_node(speed, None, build)
    }

    fn serve_node(
        speed: f64,
        link: Option<&Path>,
        build: impl FnOnce() -> VirtualNode + Send + 'static,
    ) -> NodeProc {
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let s2 = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut node = build();
            let mut pty = Pty::open().expect("a pseudo-terminal");
            tx.send(pty.path().display().to_string()).unwrap();
            let opts = ServeOptions {
                speed,
                duration: None,
            };
            pty::serve(&mut node, &mut pty, &opts, &s2).expect("serving the virtual node");
        });
        let path = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the virtual node's pty");
        let link = link.map(|l| pty::make_link(l, Path::new(&path)).expect("the symlink"));
        NodeProc {
            path,
            stop,
            thread: Some(thread),
            _link: link,
        }
    }

    /// Stop serving and close the pty: its path vanishes, as when a USB
    /// cable is pulled.
    pub fn kill9(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for NodeProc {
    fn drop(&mut self) {
        self.kill9();
    }
}
