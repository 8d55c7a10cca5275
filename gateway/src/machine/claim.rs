//! The name claim on `<prefix>/<gw>/owner` (retained): who a running
//! gateway is ([`Instance`]) and when it claimed its name ([`Claim`]). What
//! the gateway does with a claim is in [`super::owner`].

use fois_link::timefmt::unix_ms_now;
use serde::{Deserialize, Serialize};

/// Who a running gateway is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Instance {
    /// Unique per run: `<host>/<pid>/<started_unix_ms>`.
    pub instance: String,
    /// Host name.
    pub host: String,
    /// Process id.
    pub pid: u32,
    /// When this run started, Unix ms.
    pub started_unix_ms: u64,
}

impl Instance {
    /// This process, now.
    pub fn this_process() -> Instance {
        let host = crate::config::resolve::default_gateway_name();
        let pid = std::process::id();
        let started_unix_ms = unix_ms_now();
        Instance {
            instance: format!("{host}/{pid}/{started_unix_ms}"),
            host,
            pid,
            started_unix_ms,
        }
    }

    /// True when this instance started before `other` (ties broken by id).
    pub fn older_than(&self, other: &Instance) -> bool {
        (self.started_unix_ms, &self.instance) < (other.started_unix_ms, &other.instance)
    }
}

/// `<prefix>/<gw>/owner` (retained).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Claim {
    /// Gateway name.
    pub gateway: String,
    /// Who claims it.
    #[serde(flatten)]
    pub by: Instance,
    /// When the claim was made (at a connection), Unix ms.
    pub claimed_unix_ms: u64,
}
