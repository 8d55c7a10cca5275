//! The Modbus server's connected clients: a place each, and when
//! `max_clients` are connected the longest-idle one evicted to admit a new
//! master (silent connections cannot lock SCADA out); evictions counted so
//! that their warning is logged at most once per [`EVICTION_LOG_INTERVAL`].

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use tokio::task::AbortHandle;

use super::log_limit::LogLimit;

/// At most one eviction warning per this long (the count since the last).
pub const EVICTION_LOG_INTERVAL: Duration = Duration::from_secs(10);

/// The connected clients.
#[derive(Debug)]
pub struct Clients {
    next_id: u64,
    open: Vec<Client>,
    evictions: LogLimit,
}

impl Default for Clients {
    fn default() -> Clients {
        Clients {
            next_id: 0,
            open: Vec::new(),
            evictions: LogLimit::new(EVICTION_LOG_INTERVAL),
        }
    }
}

#[derive(Debug)]
struct Client {
    id: u64,
    peer: SocketAddr,
    connected: Instant,
    last_request: Option<Instant>,
    task: Option<AbortHandle>,
}

/// A client evicted to admit another.
#[derive(Debug)]
pub struct Evicted {
    /// Its address.
    pub peer: SocketAddr,
    /// Its connection's task, to abort (closing the socket).
    pub task: Option<AbortHandle>,
    /// `Some(n)`: log now that `n` clients were evicted since the last
    /// warning; `None`: counted, logged later.
    pub log: Option<u64>,
}

impl Clients {
    /// Clients connected.
    pub fn len(&self) -> usize {
        self.open.len()
    }

    /// No client is connected.
    pub fn is_empty(&self) -> bool {
        self.open.is_empty()
    }

    /// A place (its id) for `peer` at `now`. When `max` are connected, the
    /// longest-idle client leaves: one that has sent no request yet (the
    /// earliest connected first), else the one whose last request is the
    /// oldest.
    pub fn admit(&mut self, peer: SocketAddr, now: Instant, max: usize) -> (u64, Option<Evicted>) {
        let mut evicted = None;
        if self.open.len() >= max {
            let oldest = self
                .open
                .iter()
                .enumerate()
                .min_by_key(|(_, c)| {
                    (
                        c.last_request.is_some(),
                        c.last_request.unwrap_or(c.connected),
                    )
                })
                .map(|(k, _)| k);
            if let Some(k) = oldest {
                let c = self.open.swap_remove(k);
                evicted = Some(Evicted {
                    peer: c.peer,
                    task: c.task,
                    log: self.evictions.event(now),
                });
            }
        }
        let id = self.next_id;
        self.next_id += 1;
        self.open.push(Client {
            id,
            peer,
            connected: now,
            last_request: None,
            task: None,
        });
        (id, evicted)
    }

    /// The task serving client `id` (aborted if it is evicted).
    pub fn set_task(&mut self, id: u64, task: AbortHandle) {
        if let Some(c) = self.open.iter_mut().find(|c| c.id == id) {
            c.task = Some(task);
        }
    }

    /// Client `id` sent a whole request at `now`.
    pub fn request(&mut self, id: u64, now: Instant) {
        if let Some(c) = self.open.iter_mut().find(|c| c.id == id) {
            c.last_request = Some(now);
        }
    }

    /// Client `id` is gone (no-op when it was evicted).
    pub fn leave(&mut self, id: u64) {
        self.open.retain(|c| c.id != id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_idle_client_makes_room_and_the_warning_is_rate_limited() {
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let peer = |p: u16| SocketAddr::from(([10, 0, 0, 1], p));
        let mut c = Clients::default();
        let (a, _) = c.admit(peer(1), at(0), 3);
        let (b, _) = c.admit(peer(2), at(10), 3);
        let (d, none) = c.admit(peer(3), at(20), 3);
        assert!(none.is_none());
        c.request(a, at(100));
        c.request(d, at(50));
        // b never asked anything: it goes first.
        let (e, ev) = c.admit(peer(4), at(200), 3);
        let ev = ev.unwrap();
        assert_eq!((ev.peer, ev.log), (peer(2), Some(1)));
        assert_eq!(c.len(), 3);
        c.leave(b); // its task ends later: nothing happens
        assert_eq!(c.len(), 3);
        // e has not asked yet; then the oldest request: d (50 ms) before a.
        c.request(e, at(300));
        let (_, ev) = c.admit(peer(5), at(400), 3);
        assert_eq!(ev.unwrap().peer, peer(3));
        // Evictions within 10 s of the warning are counted, not logged.
        let mut logged = Vec::new();
        for k in 0..20u64 {
            let (_, ev) = c.admit(peer(6), at(1_000 + k * 1_000), 3);
            logged.extend(ev.unwrap().log);
        }
        // At 11 s (10.8 s after the first warning): the 12 since (0.4 s,
        // 1 s … 11 s); the next is due at 21 s, after the last (20 s).
        assert_eq!(logged, [12]);
        c.leave(a);
        assert_eq!(c.len(), 2);
    }
}
