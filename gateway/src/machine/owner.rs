//! One gateway per name. Two gateways that share a name overwrite each
//! other's topics (and, with the same client id, evict each other from the
//! broker every second). Each gateway claims its name: at every connection
//! it subscribes to `<prefix>/<gw>/owner` and publishes there (retained)
//! who it is: an instance id, host, pid, when it started and when it
//! claimed. A claim by another instance made *after this one started*
//! (a gateway that died before it started cannot make one) means a second
//! gateway runs under the same name:
//!
//! - the one that started later stops at once (exit code 3), without its
//!   goodbye (it must not mark the other's nodes offline), and says why;
//! - the one that started first says so loudly, claims again and, a few
//!   seconds later, publishes all its retained messages again (repairing
//!   what the other wrote).
//!
//! A restart after a crash is no conflict: the crashed instance's claim
//! was made before the new one started.
//!
//! The claim's payload ([`Claim`], [`Instance`](super::claim::Instance))
//! lives in [`super::claim`], which the gateway's record reads too.

use std::time::{Duration, Instant};

use fois_link::timefmt::{iso_utc, unix_ms_now};
use rumqttc::QoS;
use tracing::{error, warn};

use super::Gateway;
use super::claim::Claim;

/// After seeing a younger gateway of its name, the older one publishes its
/// retained messages again this long later (when the younger has stopped).
pub const REANNOUNCE_AFTER: Duration = Duration::from_secs(3);

impl Gateway {
    /// Claim the name: subscribe to the owner topic, then publish the claim
    /// (our own echo is recognised by its instance id).
    pub(super) fn claim_name(&mut self) {
        self.subscribe(self.topics.owner(), None);
        self.publish_claim();
    }

    fn publish_claim(&mut self) {
        let claim = Claim {
            gateway: self.cfg.name.clone(),
            by: self.instance.clone(),
            claimed_unix_ms: unix_ms_now(),
        };
        let payload = serde_json::to_vec(&claim).unwrap_or_default();
        self.publish_now(self.topics.owner(), payload, true, QoS::AtLeastOnce);
    }

    /// A message on the owner topic.
    pub(super) fn on_claim(&mut self, payload: &[u8], now: Instant) {
        let Ok(c) = serde_json::from_slice::<Claim>(payload) else {
            return;
        };
        if c.by.instance == self.instance.instance
            || c.claimed_unix_ms < self.instance.started_unix_ms
        {
            return;
        }
        let other = format!(
            "host {}, pid {}, started {}",
            c.by.host,
            c.by.pid,
            iso_utc(c.by.started_unix_ms)
        );
        if c.by.older_than(&self.instance) {
            let why = format!(
                "another gateway named {} runs since before this one ({other}): two gateways \
                 with one name overwrite each other's topics; this one stops. Give each \
                 gateway its own `name`",
                self.cfg.name
            );
            error!("{why}");
            self.conflict = Some(why);
        } else {
            warn!(
                "a second gateway named {} started ({other}) and publishes under this one's \
                 topics; it is told to stop (it sees this older claim) and this gateway \
                 publishes its retained messages again in {} s. Give each gateway its own `name`",
                self.cfg.name,
                REANNOUNCE_AFTER.as_secs()
            );
            self.publish_claim();
            self.reannounce_at = Some(now + REANNOUNCE_AFTER);
        }
    }

    /// Another gateway of this name started before this one: why this one
    /// must stop (the service stops without the goodbye).
    pub fn conflict(&self) -> Option<&str> {
        self.conflict.as_deref()
    }
}
