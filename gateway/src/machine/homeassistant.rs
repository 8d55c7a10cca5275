//! Home Assistant discovery of the nodes (the messages are made in
//! [`crate::discovery`]): a node's entities follow what it has sent (an ice
//! estimate, an optical gain), and the stale configs are emptied once per
//! node and run.

use fois_link::Reading;
use rumqttc::QoS;

use super::Gateway;
use crate::discovery::{self, Discovery, NodeInfo};

impl Gateway {
    /// How this gateway announces itself (None: discovery off).
    pub(super) fn discovery(&self) -> Option<Discovery<'_>> {
        let prefix = self.cfg.homeassistant_prefix.as_deref()?;
        Some(Discovery {
            prefix,
            topics: &self.topics,
            gateway: &self.cfg.name,
            version: self.cfg.homeassistant_version,
        })
    }

    /// The discovery configs of node `k` (after its `Hello`), and once per
    /// run the stale ones emptied.
    pub(super) fn announce_discovery(&mut self, k: usize) {
        let (configs, stale) = {
            let Some(d) = self.discovery() else {
                return;
            };
            let slot = &self.nodes[k];
            let (Some(name), Some(hello)) = (slot.name.as_deref(), slot.hello.as_ref()) else {
                return;
            };
            let others: Vec<_> = self.nodes.iter().map(|n| n.hello.as_ref()).collect();
            let key = discovery::hardware_key(hello, k, &others);
            let node = NodeInfo {
                name,
                key: &key,
                hello,
                estimate: slot.has_estimate,
                gain: slot.has_gain,
            };
            let stale = if slot.stale_cleared {
                Vec::new()
            } else {
                d.stale_topics(&node)
            };
            (d.node_configs(&node), stale)
        };
        if self.connected && !stale.is_empty() {
            self.nodes[k].stale_cleared = true;
            for t in stale {
                self.publish_now(t, Vec::new(), true, QoS::AtMostOnce);
            }
        }
        for (t, p) in configs {
            self.publish_now(t, p, true, QoS::AtMostOnce);
        }
    }

    /// A reading of node `k` with an estimate or a gain for the first
    /// time: announce the node again with the entities that show them.
    pub(super) fn new_entities(&mut self, k: usize, r: &Reading) {
        let slot = &mut self.nodes[k];
        let estimate = r.estimate.is_some() && !slot.has_estimate;
        let gain = r.gain.is_some() && !slot.has_gain;
        slot.has_estimate |= estimate;
        slot.has_gain |= gain;
        if estimate || gain {
            self.announce_node(k);
        }
    }
}
