//! What the Modbus TCP server answers ([`ModbusUnits::answer`]): each
//! request from the shared snapshots ([`crate::snapshot::Fleet`]), and the
//! alarm acknowledge handed to the gateway's command path
//! ([`crate::service::Service::commands`]: the node must be online, one
//! command per node per `[commands] min_interval_ms`, the answer published
//! on `<node>/command/result`).

use std::net::SocketAddr;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use tokio::sync::mpsc;
use tokio_modbus::{ExceptionCode, Request, Response};
use tracing::info;

use super::log_limit::LogLimit;

use super::clients::Clients;
use super::pdu::MAX_WRITE;
use super::{ACK, ACK_VALUE, REGISTERS, register_map};
use crate::command::FrontEndCommand;
use crate::command::NodeCommand;
use crate::config::ModbusConfig;
use crate::snapshot::Fleet;

/// At most one log line per this long for the alarm-acknowledge writes
/// handed to the command path (with their count).
pub const ACK_LOG_INTERVAL: Duration = Duration::from_secs(10);

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
}

impl ModbusUnits {
    /// A server's state over `fleet`.
    pub fn new(
        cfg: ModbusConfig,
        fleet: Fleet,
        commands: mpsc::UnboundedSender<FrontEndCommand>,
    ) -> ModbusUnits {
        ModbusUnits {
            fleet,
            cfg,
            commands,
            clients: Mutex::new(Clients::default()),
            acks_logged: Mutex::new(LogLimit::new(ACK_LOG_INTERVAL)),
        }
    }

    /// The answer to `req` for `unit` at `now` (`peer`: for the log).
    pub fn answer(
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
                self.write(k, *addr, &[*v], peer)?;
                Ok(Response::WriteSingleRegister(*addr, *v))
            }
            Request::WriteMultipleRegisters(addr, vs) => {
                self.write(k, *addr, vs, peer)?;
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

    fn write(
        &self,
        k: usize,
        addr: u16,
        vs: &[u16],
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
        if !node.link_up {
            return Err(ExceptionCode::GatewayTargetDevice);
        }
        let log = self
            .acks_logged
            .lock()
            .ok()
            .and_then(|mut l| l.event(Instant::now()));
        match log {
            Some(1) => info!(
                "Modbus: alarm acknowledge for node {} from {peer}",
                node.name.as_deref().unwrap_or(&node.port)
            ),
            Some(n) => info!(
                "Modbus: alarm acknowledge for node {} from {peer} ({n} acknowledge writes \
                 handed over since the last such line)",
                node.name.as_deref().unwrap_or(&node.port)
            ),
            None => {}
        }
        self.commands
            .send(FrontEndCommand {
                node: k,
                command: NodeCommand::AckAlarm,
            })
            .map_err(|_| ExceptionCode::ServerDeviceFailure)
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.clients.lock().map_or(0, |c| c.len())
    }
}
