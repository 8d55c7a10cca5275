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
//! **No phantom `offline`.** The second gateway's last will (retained
//! `offline` on the gateway's availability topic) fires when its
//! connection ends without a DISCONNECT — killed, or stopped while the
//! broker had just evicted it — possibly after the first has published its
//! retained messages again, and would then say `offline` for ever about a
//! gateway that runs. So each gateway also subscribes to its own
//! availability topic and, while it runs and before its goodbye, answers
//! any `offline` there with `online` again (logged at most once per
//! [`PHANTOM_LOG_INTERVAL`]). The payloads stay `online`/`offline`, as Home
//! Assistant's availability expects.
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

/// A phantom `offline` corrected is logged at most once per this long.
pub const PHANTOM_LOG_INTERVAL: Duration = Duration::from_secs(60);

impl Gateway {
    /// Claim the name: subscribe to the owner topic, then publish the claim
    /// (our own echo is recognised by its instance id).
    pub(super) fn claim_name(&mut self) {
        self.subscribe(self.topics.owner(), None);
        self.publish_claim();
    }

    /// Watch the own availability topic (after `online` was published: the
    /// retained message the subscription brings is then ours).
    pub(super) fn watch_availability(&mut self) {
        self.subscribe(self.topics.gateway_availability(), None);
    }

    /// A message on this gateway's own availability topic: an `offline`
    /// while it runs (not ours: we have not said goodbye) is corrected.
    pub(super) fn on_own_availability(&mut self, payload: &[u8], now: Instant) {
        if payload != b"offline" || self.said_goodbye || !self.connected || self.conflict.is_some()
        {
            return;
        }
        if self
            .phantom_logged
            .is_none_or(|t| now.saturating_duration_since(t) >= PHANTOM_LOG_INTERVAL)
        {
            self.phantom_logged = Some(now);
            warn!(
                "`offline` appeared on {} while this gateway runs (another instance's last \
                 will?): published `online` again",
                self.topics.gateway_availability()
            );
        }
        self.publish_now(
            self.topics.gateway_availability(),
            b"online".to_vec(),
            true,
            QoS::AtLeastOnce,
        );
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
