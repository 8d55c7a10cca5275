//! Home Assistant discovery of the nodes (the messages are made in
//! [`crate::discovery`]): a node's entities follow what it has sent (an ice
//! estimate, an optical gain), and the stale configs are emptied once per
//! node and run.

use fois_link::Reading;
use rumqttc::QoS;

use super::Gateway;
use crate::discovery::{Discovery, NodeInfo};

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
            let Some((Some(name), Some(key), Some(hello))) = self
                .fleet
                .read(k, |n| (n.name.clone(), n.key.clone(), n.hello.clone()))
            else {
                return;
            };
            let node = NodeInfo {
                name: &name,
                key: &key,
                hello: &hello,
                estimate: slot.has_estimate,
                gain: slot.has_gain,
                icing: slot.has_icing,
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

    /// A reading of node `k` with an estimate, a gain or an icing rate for the first
    /// time: announce the node again with the entities that show them.
    pub(super) fn new_entities(&mut self, k: usize, r: &Reading) {
        let slot = &mut self.nodes[k];
        let estimate = r.estimate.is_some() && !slot.has_estimate;
        let gain = r.gain.is_some() && !slot.has_gain;
        let icing = r.icing.is_some() && !slot.has_icing;
        slot.has_estimate |= estimate;
        slot.has_gain |= gain;
        slot.has_icing |= icing;
        if estimate || gain || icing {
            self.announce_node(k);
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use fois_protocol::{
        DetectorState, DeviceFrame, DeviceMsg, GainEstimate, Hello, IceEstimate, Measurement,
        MeasurementV3, Medium, PROTOCOL_VERSION, ResetReason, SeqEvent,
    };

    use super::super::{Action, Gateway};
    use crate::config::file::{FileConfig, Overrides};
    use crate::queue::{Queue, QueueLimits};
    use crate::reader::{NodeMsg, NodeUpdate};

    const ID: &str = "fois_node_cdcdcdcdcdcdcdcdcdcdcdcd";

    fn gateway(dir: &std::path::Path) -> Gateway {
        let text = format!(
            "name = \"gw\"\n[queue]\ndir = \"{}\"\n[[node]]\nport = \"/dev/a\"\nname = \"a\"\n",
            dir.display()
        );
        let cfg = FileConfig::parse(&text)
            .unwrap()
            .resolve(&Overrides::default())
            .unwrap();
        let (queue, _) = Queue::open(dir, QueueLimits::for_max_bytes(1 << 20)).unwrap();
        let fleet = crate::snapshot::Fleet::of(&cfg);
        Gateway::new(cfg, queue, fleet, Instant::now())
    }

    fn up() -> NodeMsg {
        NodeMsg {
            node: 0,
            host_unix_ms: 1_000,
            update: NodeUpdate::Up(Hello {
                protocol_version: PROTOCOL_VERSION,
                firmware_version: [1, 2, 3],
                board: Hello::board_from_str("nucleo-f446re"),
                unique_id: [0xcd; 12],
                reset_reason: ResetReason::PowerOn,
            }),
        }
    }

    /// A frame: `i1_na` (noise moves it), an estimate and a gain or not.
    fn frame(seq: u32, i1_na: i32, estimate: bool, gain: bool) -> NodeMsg {
        NodeMsg {
            node: 0,
            host_unix_ms: 2_000,
            update: NodeUpdate::Frame(
                DeviceFrame {
                    seq,
                    msg: DeviceMsg::MeasurementV3(MeasurementV3 {
                        measurement: Measurement {
                            uptime_ms: u64::from(seq) * 100,
                            i1_na,
                            i2_na: 100,
                            ambient1_na: 0,
                            ambient2_na: 0,
                            temperature_centi_c: -500,
                            vdda_mv: 3300,
                            flags: 0,
                            state: DetectorState::Dry,
                        },
                        estimate: estimate.then_some(IceEstimate {
                            thickness_um: 0,
                            sigma_um: 50,
                            medium: Medium::Dry,
                            probability_permille: 990,
                        }),
                        gain: gain.then_some(GainEstimate {
                            gain_ppm: 1_000_000,
                            sigma_ppm: 30_000,
                        }),
                    }),
                },
                SeqEvent::InOrder,
            ),
        }
    }

    /// (topic, payload empty) of every retained publish under the
    /// discovery prefix, and the state publishes.
    fn published(actions: &[Action]) -> (Vec<(String, bool)>, usize) {
        let mut discovery = Vec::new();
        let mut states = 0;
        for a in actions {
            if let Action::Publish {
                topic,
                payload,
                retain: true,
                ..
            } = a
            {
                if topic.starts_with("homeassistant/") {
                    discovery.push((topic.clone(), payload.is_empty()));
                } else if topic == "fois/gw/a/state" {
                    states += 1;
                }
            }
        }
        (discovery, states)
    }

    #[test]
    fn entities_follow_what_the_node_sends_and_stale_configs_go_once() {
        let dir = tempfile::tempdir().unwrap();
        let mut gw = gateway(dir.path());
        let t0 = Instant::now();
        gw.on_connected(t0);
        gw.actions();
        gw.on_node(up(), t0);
        let (d, _) = published(&gw.actions());
        let configs: Vec<&str> = d.iter().filter(|x| !x.1).map(|x| x.0.as_str()).collect();
        assert_eq!(configs.len(), 10, "no estimate yet: {configs:?}");
        assert!(configs.contains(&format!("homeassistant/binary_sensor/{ID}/ice/config").as_str()));
        let emptied: Vec<&str> = d.iter().filter(|x| x.1).map(|x| x.0.as_str()).collect();
        assert_eq!(
            emptied,
            [
                format!("homeassistant/button/{ID}/ack/config"),
                format!("homeassistant/button/{ID}/calibrate_dark/config"),
                "homeassistant/binary_sensor/fois_gw_a/ice/config".into(),
                "homeassistant/sensor/fois_gw_a/i1/config".into(),
                "homeassistant/sensor/fois_gw_a/i2/config".into(),
                "homeassistant/sensor/fois_gw_a/temperature/config".into(),
                "homeassistant/sensor/fois_gw_a/thickness/config".into(),
            ]
        );

        // The first estimate and gain: announced again with their entities;
        // the stale configs are not emptied twice.
        gw.on_node(frame(1, 30_000, true, true), t0);
        let (d, states) = published(&gw.actions());
        assert!(d.iter().all(|x| !x.1), "{d:?}");
        assert_eq!(d.len(), 15, "10 + thickness, water film, σ, medium, gain");
        assert!(
            d.iter()
                .any(|x| x.0 == format!("homeassistant/sensor/{ID}/gain/config"))
        );
        assert_eq!(states, 1);

        // Noise for a minute.
        for k in 0..600u32 {
            let t = t0 + Duration::from_millis(100 * u64::from(k));
            let wiggle = if k % 2 == 0 { 40 } else { -40 };
            gw.on_node(frame(2 + k, 30_000 + wiggle, true, true), t);
        }
        let (_, states) = published(&gw.actions());
        assert_eq!(
            states, 1,
            "noise under the deadbands publishes nothing; the frame counter once, 30 s in"
        );

        // A reconnection: every config again, nothing emptied.
        gw.on_disconnected("test");
        gw.on_connected(t0 + Duration::from_secs(70));
        let (d, states) = published(&gw.actions());
        let node: Vec<_> = d.iter().filter(|x| x.0.contains(ID)).collect();
        assert_eq!(node.len(), 15);
        assert!(d.iter().all(|x| !x.1));
        assert_eq!(states, 1, "the retained state again");
    }
}
