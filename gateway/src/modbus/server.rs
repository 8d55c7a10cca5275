//! The Modbus TCP server: [`tokio_modbus`]'s server skeleton on the
//! gateway's runtime, one [`Client`] per connection, every request
//! answered from the shared snapshots ([`crate::snapshot::Fleet`]) by
//! [`ModbusUnits::answer`], and the alarm acknowledge handed to the gateway's
//! command path ([`crate::service::Service::commands`]: the node must be
//! online, one command per node per `[commands] min_interval_ms`, the
//! answer published on `<node>/command/result`).
//!
//! Exceptions, as the Modbus application protocol (V1.1b3, §7) has them:
//!
//! | code | when |
//! | --- | --- |
//! | 01 illegal function | a function other than 03, 04, 06, 16; 06 and 16 while `commands = false` |
//! | 02 illegal data address | registers beyond the table; a write to a register other than `alarm_ack` |
//! | 03 illegal data value | a quantity of 0 or over 125 (read) / 123 (write); a value other than 1 written to `alarm_ack` |
//! | 0A gateway path unavailable | a unit id no node has |
//! | 0B gateway target device failed to respond | `alarm_ack` written while the node's link is down |

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use tokio::net::TcpListener;
use tokio::sync::mpsc;
use tokio_modbus::server::tcp::{Server, accept_tcp_connection};
use tokio_modbus::{ExceptionCode, Request, Response, SlaveRequest};
use tracing::{debug, info, warn};

use super::{ACK, ACK_VALUE, REGISTERS, register_map};
use crate::command::FrontEndCommand;
use crate::command::NodeCommand;
use crate::config::ModbusConfig;
use crate::snapshot::Fleet;

/// Registers one read may ask for (Modbus: 125).
pub const MAX_READ: u16 = 125;
/// Registers one write may carry (Modbus: 123).
pub const MAX_WRITE: usize = 123;

/// What the server answers from: the nodes' snapshots, the config, the
/// command path, the count of connected clients.
pub struct ModbusUnits {
    fleet: Fleet,
    cfg: ModbusConfig,
    commands: mpsc::UnboundedSender<FrontEndCommand>,
    clients: AtomicUsize,
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
            clients: AtomicUsize::new(0),
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
        info!(
            "Modbus: alarm acknowledge for node {} from {peer}",
            node.name.as_deref().unwrap_or(&node.port)
        );
        self.commands
            .send(FrontEndCommand {
                node: k,
                command: NodeCommand::AckAlarm,
            })
            .map_err(|_| ExceptionCode::ServerDeviceFailure)
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.clients.load(Ordering::Relaxed)
    }
}

/// One connection: answers its requests, frees its place when dropped.
pub struct Client {
    units: Arc<ModbusUnits>,
    peer: SocketAddr,
}

impl Client {
    /// A place for `peer`, or `None` when `max_clients` are connected.
    fn admit(units: &Arc<ModbusUnits>, peer: SocketAddr) -> Option<Client> {
        let max = units.cfg.max_clients;
        let taken = units
            .clients
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            });
        if taken.is_err() {
            warn!("Modbus: refused {peer}: {max} clients are connected (max_clients)");
            return None;
        }
        debug!("Modbus: {peer} connected");
        Some(Client {
            units: units.clone(),
            peer,
        })
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        self.units.clients.fetch_sub(1, Ordering::AcqRel);
        debug!("Modbus: {} disconnected", self.peer);
    }
}

impl tokio_modbus::server::Service for Client {
    type Request = SlaveRequest<'static>;
    type Response = Response;
    type Exception = ExceptionCode;
    type Future = std::future::Ready<Result<Response, ExceptionCode>>;

    fn call(&self, req: Self::Request) -> Self::Future {
        std::future::ready(
            self.units
                .answer(req.slave, &req.request, Instant::now(), self.peer),
        )
    }
}

/// Listen on the configured address (before the gateway runs: a taken
/// port is an error at the start, not later).
pub async fn bind(cfg: &ModbusConfig) -> anyhow::Result<TcpListener> {
    TcpListener::bind(cfg.listen)
        .await
        .map_err(|e| anyhow::anyhow!("cannot listen for Modbus TCP on {}: {e}", cfg.listen))
}

/// Serve Modbus TCP on `listener` until the task is dropped; a failing
/// `accept` (out of file descriptors) is logged and retried after a second.
pub async fn serve(listener: TcpListener, units: Arc<ModbusUnits>) {
    let server = Server::new(listener);
    let on_connected = |stream, peer| {
        let units = units.clone();
        async move { accept_tcp_connection(stream, peer, |peer| Ok(Client::admit(&units, peer))) }
    };
    loop {
        if let Err(e) = server
            .serve(&on_connected, |e| debug!("Modbus: a connection ended: {e}"))
            .await
        {
            warn!("Modbus TCP: cannot accept a connection ({e}); retrying in 1 s");
            tokio::time::sleep(std::time::Duration::from_secs(1)).await;
        }
    }
}
