//! The topic layout (documented in host/README.md, "Fleet gateway"):
//!
//! | topic | retained | QoS | payload |
//! | --- | --- | --- | --- |
//! | `<prefix>/<gw>/availability` | yes | 1 | `online` / `offline` (the gateway's last will) |
//! | `<prefix>/<gw>/status` | yes | 0 | gateway counters (JSON) |
//! | `<prefix>/<gw>/owner` | yes | 1 | which running gateway has the name (JSON; see `machine::owner`) |
//! | `<prefix>/<gw>/<node>/availability` | yes | 0 | `online` / `offline` (port lost, node silent) |
//! | `<prefix>/<gw>/<node>/info` | yes | 0 | board, firmware, protocol, unique id, port (JSON) |
//! | `<prefix>/<gw>/<node>/state` | yes | 0 | detector state, alarm, faults, ice estimate (JSON) |
//! | `<prefix>/<gw>/<node>/measurement` | no | 1 | one measurement, rate-limited (JSON) |
//! | `<prefix>/<gw>/<node>/event` | no | 1 | one event (JSON) |
//! | `<prefix>/<gw>/<node>/command` | — | — | subscribed only when commands are enabled |
//! | `<prefix>/<gw>/<node>/command/result` | no | 0 | the node's answer to a command (JSON) |

/// The topics of one gateway.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    base: String,
    command_template: Option<String>,
}

impl Topics {
    /// Topics under `<prefix>/<gateway>`; `command_template` has `{node}`.
    pub fn new(prefix: &str, gateway: &str, command_template: Option<&str>) -> Topics {
        Topics {
            base: format!("{prefix}/{gateway}"),
            command_template: command_template.map(str::to_string),
        }
    }

    /// `<prefix>/<gw>`.
    pub fn base(&self) -> &str {
        &self.base
    }

    /// The gateway's availability (and last will).
    pub fn gateway_availability(&self) -> String {
        format!("{}/availability", self.base)
    }

    /// The gateway's counters.
    pub fn gateway_status(&self) -> String {
        format!("{}/status", self.base)
    }

    /// Who runs under this gateway's name (its name claim).
    pub fn owner(&self) -> String {
        format!("{}/owner", self.base)
    }

    /// A node's availability.
    pub fn availability(&self, node: &str) -> String {
        format!("{}/{node}/availability", self.base)
    }

    /// A node's identity.
    pub fn info(&self, node: &str) -> String {
        format!("{}/{node}/info", self.base)
    }

    /// A node's retained state.
    pub fn state(&self, node: &str) -> String {
        format!("{}/{node}/state", self.base)
    }

    /// A node's measurements.
    pub fn measurement(&self, node: &str) -> String {
        format!("{}/{node}/measurement", self.base)
    }

    /// A node's events.
    pub fn event(&self, node: &str) -> String {
        format!("{}/{node}/event", self.base)
    }

    /// The command topic of a node (None: commands off).
    pub fn command(&self, node: &str) -> Option<String> {
        self.command_template
            .as_ref()
            .map(|t| t.replace("{node}", node))
    }

    /// Where the answer to a command goes.
    pub fn command_result(&self, node: &str) -> String {
        format!("{}/{node}/command/result", self.base)
    }

    /// The roll-out command (`[firmware] dir` set).
    pub fn firmware_command(&self) -> String {
        format!("{}/firmware/command", self.base)
    }

    /// A roll-out's result (retained).
    pub fn firmware_result(&self) -> String {
        format!("{}/firmware/result", self.base)
    }

    /// A node's update progress (QoS 0).
    pub fn update_progress(&self, node: &str) -> String {
        format!("{}/{node}/update/progress", self.base)
    }

    /// A node's last update result (retained).
    pub fn update_result(&self, node: &str) -> String {
        format!("{}/{node}/update/result", self.base)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout() {
        let t = Topics::new("fois", "gw1", Some("ops/{node}/do"));
        assert_eq!(t.gateway_availability(), "fois/gw1/availability");
        assert_eq!(t.gateway_status(), "fois/gw1/status");
        assert_eq!(t.owner(), "fois/gw1/owner");
        assert_eq!(t.availability("n1"), "fois/gw1/n1/availability");
        assert_eq!(t.state("n1"), "fois/gw1/n1/state");
        assert_eq!(t.measurement("n1"), "fois/gw1/n1/measurement");
        assert_eq!(t.event("n1"), "fois/gw1/n1/event");
        assert_eq!(t.info("n1"), "fois/gw1/n1/info");
        assert_eq!(t.command("n1").as_deref(), Some("ops/n1/do"));
        assert_eq!(t.command_result("n1"), "fois/gw1/n1/command/result");
        assert_eq!(Topics::new("fois", "gw1", None).command("n1"), None);
        assert_eq!(t.firmware_command(), "fois/gw1/firmware/command");
        assert_eq!(t.firmware_result(), "fois/gw1/firmware/result");
        assert_eq!(t.update_progress("n1"), "fois/gw1/n1/update/progress");
        assert_eq!(t.update_result("n1"), "fois/gw1/n1/update/result");
    }
}
