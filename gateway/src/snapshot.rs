//! Every node's latest state, readable by any front end of the gateway
//! while it runs: the MQTT side writes it, a reader such as a Modbus
//! server (one unit per node) or a health check reads it without touching
//! the MQTT state machine.
//!
//! [`Fleet`] is cheap to clone (an `Arc`); [`Fleet::nodes`] copies the
//! snapshots out under a read lock, so a reader never holds the lock while
//! it works.

use std::sync::{Arc, PoisonError, RwLock};
use std::time::{Duration, Instant};

use fois_link::Reading;
use fois_protocol::Hello;

/// One node as the gateway last saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeSnapshot {
    /// The node's position in the config (`[[node]]` tables, then `--node`
    /// flags): stable across restarts of the gateway.
    pub index: usize,
    /// The node's name in topics (`None` until a node configured without
    /// a name has connected and been named after its unique id).
    pub name: Option<String>,
    /// Its serial port.
    pub port: String,
    /// Who it is (after the first handshake; again after a restart).
    pub hello: Option<Hello>,
    /// Its key, made once from its unique id by [`key_of`]: its name when
    /// the config gives none, and what its Home Assistant ids are made of.
    pub key: Option<String>,
    /// The serial link is up (handshake done, frames arriving).
    pub link_up: bool,
    /// The latest measurement: currents, temperature, detector state,
    /// alarm and acknowledgement, faults, the ice estimate and the optical
    /// gain when the node sends them.
    pub reading: Option<Reading>,
    /// The sequence number of that measurement's frame.
    pub seq: Option<u32>,
    /// When it arrived (host clock, monotonic).
    pub received: Option<Instant>,
    /// The same, Unix ms.
    pub received_unix_ms: Option<u64>,
    /// Frames lost on the serial link since the gateway started.
    pub frames_lost: u64,
}

impl NodeSnapshot {
    /// A node not heard from yet.
    pub fn new(index: usize, name: Option<String>, port: String) -> NodeSnapshot {
        NodeSnapshot {
            index,
            name,
            port,
            hello: None,
            key: None,
            link_up: false,
            reading: None,
            seq: None,
            received: None,
            received_unix_ms: None,
            frames_lost: 0,
        }
    }

    /// Age of the latest measurement at `now` (`None`: none yet).
    pub fn age(&self, now: Instant) -> Option<Duration> {
        self.received.map(|t| now.saturating_duration_since(t))
    }
}

/// The key of node `index` with unique id `hello` among `nodes`: the id
/// in hex; when another node already has that as its key or its name (two
/// nodes with one id: virtual nodes share theirs), `-<index>` is added —
/// the config position, stable across restarts.
pub fn key_of(hello: &Hello, index: usize, nodes: &[NodeSnapshot]) -> String {
    let id = fois_link::text::unique_id_hex(hello);
    let taken = nodes.iter().any(|n| {
        n.index != index && (n.key.as_deref() == Some(&id) || n.name.as_deref() == Some(&id))
    });
    if taken { format!("{id}-{index}") } else { id }
}

/// The shared snapshots of all nodes, in config order.
#[derive(Debug, Clone, Default)]
pub struct Fleet {
    nodes: Arc<RwLock<Vec<NodeSnapshot>>>,
}

impl Fleet {
    /// The nodes of a config, not heard from yet.
    pub fn of(cfg: &crate::config::GatewayConfig) -> Fleet {
        Fleet::new(
            cfg.nodes
                .iter()
                .enumerate()
                .map(|(k, n)| NodeSnapshot::new(k, n.name.clone(), n.port.clone()))
                .collect(),
        )
    }

    /// Snapshots of nodes not heard from yet.
    pub fn new(nodes: Vec<NodeSnapshot>) -> Fleet {
        Fleet {
            nodes: Arc::new(RwLock::new(nodes)),
        }
    }

    /// A copy of every node's snapshot.
    pub fn nodes(&self) -> Vec<NodeSnapshot> {
        self.nodes
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// `f` of node `index`'s snapshot, under the read lock (`None`: no such
    /// node).
    pub fn read<R>(&self, index: usize, f: impl FnOnce(&NodeSnapshot) -> R) -> Option<R> {
        self.nodes
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .get(index)
            .map(f)
    }

    /// A copy of node `index`'s snapshot.
    pub fn node(&self, index: usize) -> Option<NodeSnapshot> {
        self.read(index, NodeSnapshot::clone)
    }

    /// Change node `index`'s snapshot (the gateway's writer side).
    pub fn update(&self, index: usize, f: impl FnOnce(&mut NodeSnapshot)) {
        let mut nodes = self.nodes.write().unwrap_or_else(PoisonError::into_inner);
        if let Some(n) = nodes.get_mut(index) {
            f(n);
        }
    }

    /// Node `index` connected with `hello`: its link up, its hello kept, its
    /// key made ([`key_of`]) when it has none or its unique id changed, and
    /// named after its key when it has no name. Its name.
    pub fn connected(&self, index: usize, hello: &Hello) -> Option<String> {
        let mut nodes = self.nodes.write().unwrap_or_else(PoisonError::into_inner);
        let same_id = nodes
            .get(index)?
            .hello
            .as_ref()
            .is_some_and(|h| h.unique_id == hello.unique_id);
        let key = match nodes[index].key.clone() {
            Some(k) if same_id => k,
            _ => key_of(hello, index, &nodes),
        };
        let n = &mut nodes[index];
        n.name.get_or_insert_with(|| key.clone());
        n.key = Some(key);
        n.hello = Some(hello.clone());
        n.link_up = true;
        n.name.clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reader_sees_what_the_writer_wrote_and_the_data_age() {
        let fleet = Fleet::new(vec![
            NodeSnapshot::new(0, Some("a".into()), "/dev/a".into()),
            NodeSnapshot::new(1, None, "/dev/b".into()),
        ]);
        let reader = fleet.clone();
        let t0 = Instant::now();
        fleet.update(1, |n| {
            n.link_up = true;
            n.seq = Some(42);
            n.received = Some(t0);
        });
        fleet.update(7, |n| n.link_up = true); // no such node: nothing
        let nodes = reader.nodes();
        assert_eq!(nodes.len(), 2);
        assert!(!nodes[0].link_up && nodes[1].link_up);
        assert_eq!(nodes[1].seq, Some(42));
        assert_eq!(
            reader.node(1).unwrap().age(t0 + Duration::from_secs(3)),
            Some(Duration::from_secs(3))
        );
        assert_eq!(reader.node(0).unwrap().age(t0), None);
    }
}
