//! The Modbus TCP server: one task per connection on the gateway's
//! runtime, reading MBAP frames ([`super::pdu`]) and answering each from
//! [`ModbusUnits::answer`].
//!
//! A connection is closed when it sends no request for `[modbus]
//! idle_timeout_s` (60 s by default), when a request is not complete
//! `frame_timeout_s` (2 s) after its first byte, when an answer cannot be
//! written within `frame_timeout_s`, and at once for an MBAP header that is
//! not Modbus (protocol id ≠ 0, length 0, 1 or over 257). When
//! `max_clients` are connected, a new connection evicts the longest-idle
//! one ([`super::clients`]). Requests to unit 0 (broadcast) are read and
//! never answered.
//!
//! Exceptions, as the Modbus application protocol (V1.1b3, §7) has them:
//!
//! | code | when |
//! | --- | --- |
//! | 01 illegal function | a function other than 03, 04, 06, 16 (codes ≥ 0x80 included); 06 and 16 while `commands = false` |
//! | 02 illegal data address | registers beyond the table; a write to a register other than `alarm_ack` |
//! | 03 illegal data value | a PDU too short or too long for its function; a quantity of 0 or over 125 (read) / 123 (write), or an FC 16 byte count that disagrees; a value other than 1 written to `alarm_ack` |
//! | 04 server device failure | `alarm_ack` written while the gateway stops |
//! | 06 server device busy | `alarm_ack` written sooner than `[commands] min_interval_ms` after the node's last command, or not taken by the gateway within 1 s |
//! | 0A gateway path unavailable | a unit id no node has |
//! | 0B gateway target device failed to respond | `alarm_ack` written while the node's link is down or it is offline |

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Instant;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::time::{timeout, timeout_at};
use tracing::{debug, warn};

use super::pdu;
pub use super::units::{MAX_READ, ModbusUnits};
use crate::config::ModbusConfig;

/// Listen on the configured address (before the gateway runs: a taken
/// port is an error at the start, not later). A std listener, so that it
/// can be bound on one thread and served on the network runtime's.
pub fn bind(cfg: &ModbusConfig) -> anyhow::Result<std::net::TcpListener> {
    std::net::TcpListener::bind(cfg.listen)
        .and_then(|l| l.set_nonblocking(true).map(|()| l))
        .map_err(|e| anyhow::anyhow!("cannot listen for Modbus TCP on {}: {e}", cfg.listen))
}

/// Serve Modbus TCP on `listener` until the task is dropped; a failing
/// `accept` (out of file descriptors) is logged and retried after a second.
/// Run it on a runtime that does no disk IO (the gateway's network
/// runtime, [`crate::service`]).
pub async fn serve(listener: std::net::TcpListener, units: Arc<ModbusUnits>) {
    let listener = match TcpListener::from_std(listener) {
        Ok(l) => l,
        Err(e) => {
            warn!("Modbus TCP: cannot serve the listening socket ({e})");
            return;
        }
    };
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(c) => c,
            Err(e) => {
                warn!("Modbus TCP: cannot accept a connection ({e}); retrying in 1 s");
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                continue;
            }
        };
        let Ok(mut clients) = units.clients.lock() else {
            return;
        };
        let (id, evicted) = clients.admit(peer, Instant::now(), units.cfg.max_clients);
        if let Some(ev) = evicted {
            if let Some(task) = ev.task {
                task.abort();
            }
            debug!("Modbus: closed {} to admit {peer} (max_clients)", ev.peer);
            if let Some(n) = ev.log {
                warn!(
                    "Modbus: {} clients connected (max_clients): closed the longest-idle \
                     connection to admit a new one, {n} time(s) since the last such warning",
                    units.cfg.max_clients
                );
            }
        }
        // Answers go out at once (Nagle would hold an answer back until
        // the previous one is acknowledged).
        let _ = stream.set_nodelay(true);
        debug!("Modbus: {peer} connected");
        let task = tokio::spawn(connection(
            stream,
            peer,
            Place {
                units: units.clone(),
                id,
            },
        ));
        clients.set_task(id, task.abort_handle());
    }
}

/// A client's place among the connected: freed when its task ends or is
/// aborted.
struct Place {
    units: Arc<ModbusUnits>,
    id: u64,
}

impl Drop for Place {
    fn drop(&mut self) {
        if let Ok(mut c) = self.units.clients.lock() {
            c.leave(self.id);
        }
    }
}

/// Serve one connection until it closes, times out or sends a header that
/// is not Modbus.
async fn connection(mut stream: TcpStream, peer: SocketAddr, place: Place) {
    let units = &place.units;
    let (idle, frame) = (units.cfg.idle_timeout, units.cfg.frame_timeout);
    let mut head = [0u8; pdu::HEADER];
    let mut body = [0u8; pdu::MAX_LENGTH as usize];
    loop {
        match timeout(idle, stream.read(&mut head[..1])).await {
            Err(_) => {
                debug!("Modbus: {peer} closed: silent for {idle:?}");
                return;
            }
            Ok(Ok(0) | Err(_)) => return,
            Ok(Ok(_)) => {}
        }
        let deadline = tokio::time::Instant::now() + frame;
        if !matches!(
            timeout_at(deadline, stream.read_exact(&mut head[1..])).await,
            Ok(Ok(_))
        ) {
            debug!("Modbus: {peer} closed: a header not complete within {frame:?}");
            return;
        }
        let Some(h) = pdu::header(&head) else {
            debug!("Modbus: {peer} closed: not a Modbus header {head:02x?}");
            return;
        };
        let Some(request) = body.get_mut(..h.pdu_len) else {
            return;
        };
        if !matches!(
            timeout_at(deadline, stream.read_exact(request)).await,
            Ok(Ok(_))
        ) {
            debug!("Modbus: {peer} closed: a request not complete within {frame:?}");
            return;
        }
        let now = Instant::now();
        if let Ok(mut c) = units.clients.lock() {
            c.request(place.id, now);
        }
        if h.unit == 0 {
            continue; // broadcast: never answered
        }
        let function = request.first().copied().unwrap_or(0);
        let answer = match pdu::request(request) {
            Ok(r) => units.answer(h.unit, &r, now, peer).await,
            Err(e) => Err(e),
        };
        let out = pdu::frame(h.transaction, h.unit, &pdu::response(function, answer));
        if !matches!(timeout(frame, stream.write_all(&out)).await, Ok(Ok(()))) {
            debug!("Modbus: {peer} closed: the answer not taken within {frame:?}");
            return;
        }
    }
}
