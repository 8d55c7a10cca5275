//! Packet-id bookkeeping: which queue record a broker's PUBACK acknowledges.
//!
//! The event loop reports every publish it sends as `Outgoing::Publish(pkid)`,
//! in the order the requests were handed to the client (QoS 0 ones with
//! packet id 0); a FIFO of "which record was that request" turns the packet
//! id into a record index. At most [`WINDOW`] records are unacknowledged at
//! once, fewer than the client's packet-id space
//! ([`crate::mqtt::INFLIGHT`]), so a packet id is never reused while in
//! flight. Records are acknowledged to the queue in order: the acknowledged
//! offset moves only past a run of acknowledged records. On a lost
//! connection everything in flight is forgotten and sent again from the
//! queue after the reconnect.

use std::collections::{HashMap, VecDeque};

/// Records published and not yet acknowledged, at most.
pub const WINDOW: usize = 512;

/// Requests handed to the client, and records in flight with their
/// acknowledgement.
#[derive(Debug, Default)]
pub struct InFlight {
    fifo: VecDeque<Option<u64>>,
    pkids: HashMap<u16, u64>,
    sent: VecDeque<(u64, bool)>,
}

impl InFlight {
    /// A publish request was handed to the client: a record, or `None` for
    /// anything else that produces an `Outgoing::Publish`.
    pub fn requested(&mut self, record: Option<u64>) {
        self.fifo.push_back(record);
        if let Some(i) = record {
            self.sent.push_back((i, false));
        }
    }

    /// The newest request did not reach the client after all (its request
    /// channel refused it): forget it. Returns its record, if it was one.
    pub fn unrequest_last(&mut self) -> Option<u64> {
        let record = self.fifo.pop_back()??;
        if self.sent.back().is_some_and(|s| s.0 == record) {
            self.sent.pop_back();
        }
        Some(record)
    }

    /// The event loop sent a publish with this packet id.
    pub fn outgoing(&mut self, pkid: u16) {
        if let Some(Some(i)) = self.fifo.pop_front()
            && pkid != 0
        {
            self.pkids.insert(pkid, i);
        }
    }

    /// A PUBACK arrived; returns the new acknowledged offset (every record
    /// below it is acknowledged) when it moved.
    pub fn acked(&mut self, pkid: u16) -> Option<u64> {
        let i = self.pkids.remove(&pkid)?;
        if let Ok(k) = self.sent.binary_search_by_key(&i, |s| s.0) {
            self.sent[k].1 = true;
        }
        let mut upto = None;
        while let Some(&(i, true)) = self.sent.front() {
            upto = Some(i + 1);
            self.sent.pop_front();
        }
        upto
    }

    /// Records sent and not acknowledged.
    pub fn unacked(&self) -> usize {
        self.sent.len()
    }

    /// The connection is gone: forget everything in flight.
    pub fn clear(&mut self) {
        *self = InFlight::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packet_ids_map_to_records_and_acknowledge_in_order() {
        let mut f = InFlight::default();
        f.requested(Some(10));
        f.requested(None); // a retained message between records
        f.requested(Some(11));
        f.requested(Some(12));
        f.outgoing(1);
        f.outgoing(0); // QoS 0: no packet id
        f.outgoing(2);
        f.outgoing(3);
        assert_eq!(f.unacked(), 3);
        // Out of order: 12 first: the offset may not move past 10.
        assert_eq!(f.acked(3), None);
        assert_eq!(f.acked(1), Some(11));
        assert_eq!(f.acked(2), Some(13));
        assert_eq!(f.unacked(), 0);
        // An unknown packet id (the QoS 1 availability) changes nothing.
        assert_eq!(f.acked(77), None);
    }

    #[test]
    fn a_request_the_client_refused_is_forgotten() {
        let mut f = InFlight::default();
        f.requested(Some(4));
        f.requested(None);
        f.requested(Some(5));
        assert_eq!(f.unrequest_last(), Some(5));
        assert_eq!(f.unrequest_last(), None, "the retained message");
        assert_eq!(f.unacked(), 1);
        f.outgoing(9);
        assert_eq!(f.acked(9), Some(5), "record 4 is acknowledged");
    }
}
