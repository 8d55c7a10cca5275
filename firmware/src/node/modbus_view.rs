//! The node as its Modbus registers show it ([`Node::modbus_view`]: the
//! measurement block by the one mapping the gateway uses too), and the
//! actions of a Modbus write carried out ([`Node::modbus_action`]: through
//! the same command path as the framed link's).

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use fois_protocol::registers::{
    self, CommandResult, FRAMES_LOST, IcingRate, NA_U32, Sample, measurement_registers, status,
};

use super::Node;
use crate::hal::PhotoAdc;
use crate::modbus::view::{Action, ModbusView, command_result};
use crate::storage::Storage;
use crate::update::UpdateSlots;

impl<A, L, AL, IND, D, S, U> Node<A, L, AL, IND, D, S, U>
where
    A: PhotoAdc,
    L: OutputPin,
    AL: OutputPin,
    IND: OutputPin,
    D: DelayNs,
    S: Storage,
    U: UpdateSlots,
{
    /// The registers, config and link settings as a Modbus master reads
    /// them now. The gateway-only registers (data age, frames lost) read
    /// "not available"; the link-up bit is set (the node is answering);
    /// stale means no measurement yet. The icing rate reads "not
    /// available" until the frame carries one.
    pub fn modbus_view(&self) -> ModbusView {
        let mut r = registers::not_available();
        registers::set32(&mut r, FRAMES_LOST, NA_U32);
        registers::set(&mut r, registers::STATUS, status::LINK_UP | status::STALE);
        if let (Some(m), Some(rep)) = (self.last.as_ref(), self.last_report.as_ref()) {
            registers::set(&mut r, registers::STATUS, status::LINK_UP);
            measurement_registers(
                &mut r,
                &Sample {
                    measurement: m,
                    seq: rep.seq,
                    estimate: rep.estimate.as_ref(),
                    gain: rep.gain.as_ref(),
                    icing: rep.icing.as_ref().map(IcingRate::from),
                },
            );
        }
        ModbusView {
            registers: r,
            config: self.config.clone(),
            link: self.link,
        }
    }

    /// Carry out a Modbus write's action (after its answer went out) and
    /// give what [`registers::LAST_RESULT`] shows. The framed link's
    /// commands do the same work (`Node::command`).
    pub fn modbus_action(&mut self, action: Action, now_ms: u64) -> CommandResult {
        self.trial.link_answered();
        command_result(&self.command(action.command(), now_ms))
    }
}
