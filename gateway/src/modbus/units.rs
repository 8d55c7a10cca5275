//! What the Modbus TCP server answers ([`ModbusUnits::answer`]): each
//! request from the shared snapshots ([`crate::snapshot::Fleet`]), and the
//! alarm acknowledge handed to the gateway's command path
//! ([`crate::service::Service::commands`]: the node must be online, one
//! command per node per `[commands] min_interval_ms`, the answer published
//! on `<node>/command/result`).
//!
//! An acknowledge write is answered only once the state machine has
//! handed it to the node: a refusal is an exception, never a success.
//! Writes sooner than `min_interval_ms` after the last one this server
//! handed over for the node are refused here (06), without reaching the
//! state machine: a flood of writes makes no MQTT results and no log line
//! per write (refusals are logged at most once per [`REFUSAL_LOG_INTERVAL`],
//! with their count).

use std::net::SocketAddr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, oneshot};
use tokio_modbus::{ExceptionCode, Request, Response};
use tracing::{info, warn};

use super::log_limit::LogLimit;

use super::clients::Clients;
use super::pdu::MAX_WRITE;
use super::{ACK, ACK_VALUE, REGISTERS, register_map};
use crate::command::{FrontEndCommand, NodeCommand, Refusal};
use crate::config::ModbusConfig;
use crate::snapshot::Fleet;

/// At most one log line per this long for the alarm-acknowledge writes
/// handed to the command path (with their count).
pub const ACK_LOG_INTERVAL: Duration = Duration::from_secs(10);

/// At most one log line per this long for refused acknowledge writes
/// (with their count).
pub const REFUSAL_LOG_INTERVAL: Duration = Duration::from_secs(10);

/// The state machine must say within this long whether it handed an
/// acknowledge to the node; else the write is answered 06 (busy) and the
/// command dropped (not carried out later).
pub const ACK_REPLY_TIMEOUT: Duration = Duration::from_secs(1);

/// Registers one read may ask for (Modbus: 125).
pub const MAX_READ: u16 = 125;

/// What the server answers from: the nodes' snapshots, the config, the
/// command path, the connected clients.
pub struct ModbusUnits {
    fleet: Fleet,
    pub(super) cfg: ModbusConfig,
    commands: mpsc::UnboundedSender<FrontEndCommand>,
    pub(super) clients: Mutex<Clients>,
    acks_logged: Mutex<LogLimit>,
    refusals_logged: Mutex<LogLimit>,
    /// `[commands] min_interval_ms`.
    ack_min_interval: Duration,
    /// When this server last handed an acknowledge over, per node.
    last_ack: Mutex<Vec<Option<Instant>>>,
}

impl ModbusUnits {
    /// A server's state over `fleet`; acknowledge writes at most one per
    /// node per `ack_min_interval` (`[commands] min_interval_ms`).
    pub fn new(
        cfg: ModbusConfig,
        fleet: Fleet,
        commands: mpsc::UnboundedSender<FrontEndCommand>,
        ack_min_interval: Duration,
    ) -> ModbusUnits {
        ModbusUnits {
            last_ack: Mutex::new(vec![None; cfg.units.len()]),
            fleet,
            cfg,
            commands,
            clients: Mutex::new(Clients::default()),
            acks_logged: Mutex::new(LogLimit::new(ACK_LOG_INTERVAL)),
            refusals_logged: Mutex::new(LogLimit::new(REFUSAL_LOG_INTERVAL)),
            ack_min_interval,
        }
    }

    /// The answer to `req` for `unit` at `now` (`peer`: for the log); an
    /// acknowledge write waits for the state machine (at most
    /// [`ACK_REPLY_TIMEOUT`]).
    pub async fn answer(
        &self,
        unit: u8,
        req: &Request<'_>,
        now: Instant,
        peer: SocketAddr,
    ) -> Result<Response, ExceptionCode> {
        let Some(k) = self.cfg.node_of_unit(unit) else {
            return Err(ExceptionCode::GatewayPathUnavailable);
        };
        match req {
            Request::ReadInputRegisters(addr, n) => self
                .read(k, *addr, *n, now)
                .map(Response::ReadInputRegisters),
            Request::ReadHoldingRegisters(addr, n) => self
                .read(k, *addr, *n, now)
                .map(Response::ReadHoldingRegisters),
            Request::WriteSingleRegister(addr, v) => {
                self.write(k, *addr, &[*v], now, peer).await?;
                Ok(Response::WriteSingleRegister(*addr, *v))
            }
            Request::WriteMultipleRegisters(addr, vs) => {
                self.write(k, *addr, vs, now, peer).await?;
                Ok(Response::WriteMultipleRegisters(*addr, vs.len() as u16))
            }
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }

    fn read(&self, k: usize, addr: u16, n: u16, now: Instant) -> Result<Vec<u16>, ExceptionCode> {
        if n == 0 || n > MAX_READ {
            return Err(ExceptionCode::IllegalDataValue);
        }
        let (start, end) = (usize::from(addr), usize::from(addr) + usize::from(n));
        if end > REGISTERS {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        let node = self
            .fleet
            .node(k)
            .ok_or(ExceptionCode::ServerDeviceFailure)?;
        Ok(register_map(&node, now, self.cfg.stale_after)[start..end].to_vec())
    }

    async fn write(
        &self,
        k: usize,
        addr: u16,
        vs: &[u16],
        now: Instant,
        peer: SocketAddr,
    ) -> Result<(), ExceptionCode> {
        if !self.cfg.commands {
            return Err(ExceptionCode::IllegalFunction);
        }
        if vs.is_empty() || vs.len() > MAX_WRITE {
            return Err(ExceptionCode::IllegalDataValue);
        }
        if addr != ACK || vs.len() != 1 {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        if vs[0] != ACK_VALUE {
            return Err(ExceptionCode::IllegalDataValue);
        }
        let node = self
            .fleet
            .node(k)
            .ok_or(ExceptionCode::ServerDeviceFailure)?;
        let name = node.name.as_deref().unwrap_or(&node.port);
        if !node.link_up {
            return Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::GatewayTargetDevice,
                "the node's link is down",
            ));
        }
        // One acknowledge per node per min_interval from here; the state
        // machine checks again (an MQTT command may have come between).
        let admitted = self.last_ack.lock().ok().is_some_and(|mut last| {
            let Some(slot) = last.get_mut(k) else {
                return false;
            };
            let free =
                slot.is_none_or(|t| now.saturating_duration_since(t) >= self.ack_min_interval);
            if free {
                *slot = Some(now);
            }
            free
        });
        if !admitted {
            return Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::ServerDeviceBusy,
                "rate limit",
            ));
        }
        let log = self.acks_logged.lock().ok().and_then(|mut l| l.event(now));
        match log {
            Some(1) => info!("Modbus: alarm acknowledge for node {name} from {peer}"),
            Some(n) => info!(
                "Modbus: alarm acknowledge for node {name} from {peer} ({n} acknowledge writes \
                 handed over since the last such line)"
            ),
            None => {}
        }
        let (reply, answer) = oneshot::channel();
        let sent = self.commands.send(FrontEndCommand {
            node: k,
            command: NodeCommand::AckAlarm,
            reply: Some(reply),
        });
        if sent.is_err() {
            return Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::ServerDeviceFailure,
                "the gateway is stopping",
            ));
        }
        match tokio::time::timeout(ACK_REPLY_TIMEOUT, answer).await {
            Ok(Ok(Ok(()))) => Ok(()),
            Ok(Ok(Err(Refusal::RateLimit))) => Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::ServerDeviceBusy,
                "rate limit (a command from MQTT)",
            )),
            Ok(Ok(Err(Refusal::Offline))) => Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::GatewayTargetDevice,
                "the node is offline",
            )),
            Ok(Err(_)) => Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::ServerDeviceFailure,
                "the gateway is stopping",
            )),
            Err(_) => Err(self.refused(
                name,
                peer,
                now,
                ExceptionCode::ServerDeviceBusy,
                "the gateway did not take it within 1 s",
            )),
        }
    }

    /// Count (and log, at most once per [`REFUSAL_LOG_INTERVAL`]) a refused
    /// acknowledge write; the exception that answers it.
    fn refused(
        &self,
        name: &str,
        peer: SocketAddr,
        now: Instant,
        code: ExceptionCode,
        why: &str,
    ) -> ExceptionCode {
        let log = self
            .refusals_logged
            .lock()
            .ok()
            .and_then(|mut l| l.event(now));
        if let Some(n) = log {
            warn!(
                "Modbus: alarm acknowledge for node {name} from {peer} refused ({why}; \
                 exception {:02X}); {n} acknowledge write(s) refused since the last such line",
                u8::from(code)
            );
        }
        code
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.clients.lock().map_or(0, |c| c.len())
    }
}
