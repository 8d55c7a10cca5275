//! [`ModbusUnits::answer`]: reads, and acknowledge writes with a stand-in
//! for the state machine's reply.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::sync::mpsc;
use tokio_modbus::{ExceptionCode, Request, Response};

use super::super::units::{ModbusUnits, REFUSAL_LOG_INTERVAL};
use super::iced;
use crate::command::{FrontEndCommand, NodeCommand, Refusal};
use crate::config::ModbusConfig;
use crate::snapshot::{Fleet, NodeSnapshot};
use crate::test_log::Capture;

/// `[commands] min_interval_ms` of these tests.
const MIN_INTERVAL: Duration = Duration::from_secs(5);

fn units(
    commands: bool,
) -> (
    ModbusUnits,
    mpsc::UnboundedReceiver<FrontEndCommand>,
    Instant,
) {
    let t0 = Instant::now();
    let mut down = NodeSnapshot::new(1, Some("down".into()), "/dev/y".into());
    down.link_up = false;
    let fleet = Fleet::new(vec![iced(t0), down]);
    let cfg = ModbusConfig {
        listen: "127.0.0.1:5020".parse().unwrap(),
        commands,
        stale_after: Duration::from_secs(2),
        max_clients: 4,
        idle_timeout: Duration::from_secs(60),
        frame_timeout: Duration::from_secs(2),
        units: vec![5, 9],
    };
    let (tx, rx) = mpsc::unbounded_channel();
    (ModbusUnits::new(cfg, fleet, tx, MIN_INTERVAL), rx, t0)
}

const PEER: SocketAddr = SocketAddr::new(std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST), 4242);

async fn ask(
    u: &ModbusUnits,
    unit: u8,
    r: Request<'static>,
    now: Instant,
) -> Result<Response, ExceptionCode> {
    u.answer(unit, &r, now, PEER).await
}

/// The state machine's stand-in: answers each command with the next of
/// `replies` (the last one for ever after); the commands it got.
fn state_machine(
    mut rx: mpsc::UnboundedReceiver<FrontEndCommand>,
    replies: Vec<Option<Result<(), Refusal>>>,
) -> Arc<Mutex<Vec<(usize, NodeCommand)>>> {
    let got = Arc::new(Mutex::new(Vec::new()));
    let seen = got.clone();
    tokio::spawn(async move {
        let mut k = 0;
        let mut held = Vec::new();
        while let Some(c) = rx.recv().await {
            seen.lock().unwrap().push((c.node, c.command));
            let reply = replies.get(k).or(replies.last()).copied().flatten();
            k += 1;
            match (reply, c.reply) {
                (Some(r), Some(tx)) => {
                    let _ = tx.send(r);
                }
                // No answer (a stalled state machine): held unanswered.
                (None, Some(tx)) => held.push(tx),
                _ => {}
            }
        }
    });
    got
}

#[tokio::test]
async fn reads_of_either_function_give_the_same_registers_and_bad_ones_the_modbus_exception() {
    let (u, _rx, t0) = units(false);
    let now = t0 + Duration::from_millis(500);
    let u = &u;
    let ask = |unit, r| ask(u, unit, r, now);
    assert_eq!(
        ask(5, Request::ReadInputRegisters(7, 5)).await,
        Ok(Response::ReadInputRegisters(vec![0xFE00, 1250, 80, 3, 930]))
    );
    assert_eq!(
        ask(5, Request::ReadHoldingRegisters(7, 5)).await,
        Ok(Response::ReadHoldingRegisters(vec![
            0xFE00, 1250, 80, 3, 930
        ]))
    );
    assert_eq!(
        ask(5, Request::ReadInputRegisters(0, 24))
            .await
            .map(|r| match r {
                Response::ReadInputRegisters(v) => v.len(),
                _ => 0,
            }),
        Ok(24)
    );
    use ExceptionCode::*;
    for (unit, r, want) in [
        (5, Request::ReadInputRegisters(26, 2), IllegalDataAddress),
        (5, Request::ReadHoldingRegisters(100, 1), IllegalDataAddress),
        (5, Request::ReadInputRegisters(0, 0), IllegalDataValue),
        (5, Request::ReadInputRegisters(0, 126), IllegalDataValue),
        (1, Request::ReadInputRegisters(0, 1), GatewayPathUnavailable),
        (5, Request::ReadCoils(0, 1), IllegalFunction),
        // Read-only: writes are an illegal function, even the ack register.
        (5, Request::WriteSingleRegister(23, 1), IllegalFunction),
        (
            5,
            Request::WriteMultipleRegisters(23, vec![1].into()),
            IllegalFunction,
        ),
    ] {
        let shown = format!("{r:?}");
        assert_eq!(ask(unit, r).await, Err(want), "{shown}");
    }
}

#[tokio::test]
async fn an_acknowledge_is_a_success_only_when_the_state_machine_handed_it_to_the_node() {
    let (u, rx, t0) = units(true);
    let at = |s: u64| t0 + Duration::from_secs(s);
    let got = state_machine(
        rx,
        vec![
            Some(Ok(())),
            Some(Ok(())),
            Some(Err(Refusal::RateLimit)),
            Some(Err(Refusal::Offline)),
            None,
        ],
    );
    let u = &u;
    let ask = |unit, r, s| ask(u, unit, r, at(s));
    use ExceptionCode::*;
    assert_eq!(
        ask(5, Request::WriteSingleRegister(22, 1), 0).await,
        Err(IllegalDataAddress)
    );
    assert_eq!(
        ask(5, Request::WriteMultipleRegisters(22, vec![0, 1].into()), 0).await,
        Err(IllegalDataAddress)
    );
    assert_eq!(
        ask(5, Request::WriteSingleRegister(23, 2), 0).await,
        Err(IllegalDataValue)
    );
    assert_eq!(
        ask(9, Request::WriteSingleRegister(23, 1), 0).await,
        Err(GatewayTargetDevice),
        "the link is down"
    );
    assert!(got.lock().unwrap().is_empty(), "nothing handed over yet");
    assert_eq!(
        ask(5, Request::WriteSingleRegister(23, 1), 0).await,
        Ok(Response::WriteSingleRegister(23, 1))
    );
    // Sooner than min_interval: busy, without asking the state machine.
    assert_eq!(
        ask(5, Request::WriteMultipleRegisters(23, vec![1].into()), 4).await,
        Err(ServerDeviceBusy)
    );
    assert_eq!(got.lock().unwrap().len(), 1);
    assert_eq!(
        ask(5, Request::WriteMultipleRegisters(23, vec![1].into()), 5).await,
        Ok(Response::WriteMultipleRegisters(23, 1))
    );
    // The state machine refuses (an MQTT command came between; the node
    // went offline): the exception says so.
    assert_eq!(
        ask(5, Request::WriteSingleRegister(23, 1), 10).await,
        Err(ServerDeviceBusy)
    );
    assert_eq!(
        ask(5, Request::WriteSingleRegister(23, 1), 15).await,
        Err(GatewayTargetDevice)
    );
    // No answer within 1 s: busy (the command is not carried out later:
    // its waiter is gone, which the service checks).
    let t = Instant::now();
    assert_eq!(
        ask(5, Request::WriteSingleRegister(23, 1), 20).await,
        Err(ServerDeviceBusy)
    );
    let waited = t.elapsed();
    assert!(
        (Duration::from_millis(990)..Duration::from_millis(1_500)).contains(&waited),
        "{waited:?}"
    );
    assert_eq!(
        *got.lock().unwrap(),
        vec![(0, NodeCommand::AckAlarm); 5],
        "five handed over"
    );
}

#[tokio::test]
async fn an_acknowledge_flood_is_refused_busy_with_bounded_logs_and_commands() {
    let log = Capture::start();
    let (u, rx, t0) = units(true);
    let got = state_machine(rx, vec![Some(Ok(()))]);
    // 2 000 writes per second for 12 s.
    let mut ok = Vec::new();
    let mut busy = 0;
    for k in 0..24_000u64 {
        let at = t0 + Duration::from_micros(k * 500);
        match u
            .answer(5, &Request::WriteSingleRegister(23, 1), at, PEER)
            .await
        {
            Ok(_) => ok.push(k / 2_000),
            Err(ExceptionCode::ServerDeviceBusy) => busy += 1,
            Err(e) => panic!("{e:?}"),
        }
    }
    // One per 5 s handed over and answered; every other write 06.
    assert_eq!(ok, [0, 5, 10]);
    assert_eq!(busy, 24_000 - 3);
    assert_eq!(got.lock().unwrap().len(), 3);
    let lines = log.lines();
    let text = lines.join("\n");
    let refusals: Vec<&String> = lines.iter().filter(|l| l.contains("refused")).collect();
    let handed: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("alarm acknowledge") && !l.contains("refused"))
        .collect();
    // Refusals logged at 0 s and 10 s (every 10 s), acknowledges at 0 and 10 s.
    assert_eq!(REFUSAL_LOG_INTERVAL, Duration::from_secs(10));
    assert_eq!(refusals.len(), 2, "{text}");
    assert!(refusals[0].contains("exception 06"), "{}", refusals[0]);
    // From 0.5 ms to 10.0005 s: 20 000 writes, two of them handed over.
    assert!(
        refusals[1].contains("19998 acknowledge write(s) refused"),
        "{}",
        refusals[1]
    );
    assert_eq!(handed.len(), 2, "{text}");
    assert_eq!(lines.len(), 4, "{text}");
}
