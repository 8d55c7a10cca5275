//! Modbus TCP framing, parsed by hand so that every malformed request gets
//! the exception the Modbus application protocol (V1.1b3, §7) asks for
//! instead of a closed connection: the MBAP header (§4.1 of the Modbus
//! messaging on TCP/IP guide), the request PDUs of the functions the
//! gateway serves (03, 04, 06, 16) into [`tokio_modbus`]'s [`Request`], and
//! a [`Response`] or an [`ExceptionCode`] back into bytes.

use std::borrow::Cow;

use tokio_modbus::{ExceptionCode, Request, Response};

/// Bytes of the MBAP header (transaction, protocol, length, unit).
pub const HEADER: usize = 7;
/// The longest PDU Modbus allows (an ADU of 260 bytes).
pub const MAX_PDU: usize = 253;
/// The largest MBAP length field read (unit id + PDU): three bytes over
/// Modbus's 254, so that an FC 16 of 124 registers (PDU of 254 bytes) is
/// read whole and answered 03; a larger length closes the connection (the
/// stream cannot be resynchronised).
pub const MAX_LENGTH: u16 = 257;

/// Registers one write may carry (Modbus: 123).
pub const MAX_WRITE: usize = 123;

/// An MBAP header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Header {
    /// The transaction id, echoed in the answer.
    pub transaction: u16,
    /// The unit id (0: broadcast).
    pub unit: u8,
    /// Bytes of the PDU that follows (1..=256).
    pub pdu_len: usize,
}

/// The header in `b`, or `None` when it is not Modbus (protocol id other
/// than 0) or its length is 0, 1 (no function code) or over [`MAX_LENGTH`].
pub fn header(b: &[u8; HEADER]) -> Option<Header> {
    let protocol = u16::from_be_bytes([b[2], b[3]]);
    let length = u16::from_be_bytes([b[4], b[5]]);
    if protocol != 0 || !(2..=MAX_LENGTH).contains(&length) {
        return None;
    }
    Some(Header {
        transaction: u16::from_be_bytes([b[0], b[1]]),
        unit: b[6],
        pdu_len: usize::from(length) - 1,
    })
}

/// The request in `pdu` (function code first): 01 for a function other
/// than 03, 04, 06, 16 (exception responses, ≥ 0x80, included); 03 for a
/// PDU too short or too long for its function, over [`MAX_PDU`], or an
/// FC 16 whose quantity is 0 or over [`MAX_WRITE`] or disagrees with its
/// byte count.
pub fn request(pdu: &[u8]) -> Result<Request<'static>, ExceptionCode> {
    let Some((&function, data)) = pdu.split_first() else {
        return Err(ExceptionCode::IllegalDataValue);
    };
    let words = |b: &[u8]| -> Vec<u16> {
        b.chunks_exact(2)
            .map(|w| u16::from_be_bytes([w[0], w[1]]))
            .collect()
    };
    match function {
        0x03 | 0x04 | 0x06 | 0x10 if pdu.len() > MAX_PDU => Err(ExceptionCode::IllegalDataValue),
        0x03 | 0x04 | 0x06 => {
            let &[a0, a1, v0, v1] = data else {
                return Err(ExceptionCode::IllegalDataValue);
            };
            let (addr, v) = (u16::from_be_bytes([a0, a1]), u16::from_be_bytes([v0, v1]));
            Ok(match function {
                0x03 => Request::ReadHoldingRegisters(addr, v),
                0x04 => Request::ReadInputRegisters(addr, v),
                _ => Request::WriteSingleRegister(addr, v),
            })
        }
        0x10 => {
            let Some((&[a0, a1, n0, n1, count], values)) = data.split_first_chunk::<5>() else {
                return Err(ExceptionCode::IllegalDataValue);
            };
            let n = usize::from(u16::from_be_bytes([n0, n1]));
            if n == 0 || n > MAX_WRITE || usize::from(count) != 2 * n || values.len() != 2 * n {
                return Err(ExceptionCode::IllegalDataValue);
            }
            Ok(Request::WriteMultipleRegisters(
                u16::from_be_bytes([a0, a1]),
                Cow::Owned(words(values)),
            ))
        }
        _ => Err(ExceptionCode::IllegalFunction),
    }
}

/// The PDU answering a request of `function`: the response, or the
/// exception (function | 0x80, code).
pub fn response(function: u8, answer: Result<Response, ExceptionCode>) -> Vec<u8> {
    let registers = |f: u8, rs: &[u16]| -> Option<Vec<u8>> {
        let count = u8::try_from(rs.len() * 2).ok()?;
        let mut out = vec![f, count];
        out.extend(rs.iter().flat_map(|r| r.to_be_bytes()));
        Some(out)
    };
    let two = |f: u8, a: u16, b: u16| {
        let ([a0, a1], [b0, b1]) = (a.to_be_bytes(), b.to_be_bytes());
        Some(vec![f, a0, a1, b0, b1])
    };
    let pdu = match answer {
        Ok(Response::ReadHoldingRegisters(rs)) => registers(0x03, &rs),
        Ok(Response::ReadInputRegisters(rs)) => registers(0x04, &rs),
        Ok(Response::WriteSingleRegister(a, v)) => two(0x06, a, v),
        Ok(Response::WriteMultipleRegisters(a, n)) => two(0x10, a, n),
        Ok(_) => None,
        Err(e) => Some(vec![function | 0x80, u8::from(e)]),
    };
    pdu.unwrap_or_else(|| {
        vec![
            function | 0x80,
            u8::from(ExceptionCode::ServerDeviceFailure),
        ]
    })
}

/// The ADU carrying `pdu` for `transaction` and `unit`.
pub fn frame(transaction: u16, unit: u8, pdu: &[u8]) -> Vec<u8> {
    let length = u16::try_from(pdu.len() + 1).unwrap_or(u16::MAX);
    let mut out = Vec::with_capacity(HEADER + pdu.len());
    out.extend(transaction.to_be_bytes());
    out.extend([0, 0]);
    out.extend(length.to_be_bytes());
    out.push(unit);
    out.extend(pdu);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_outside_modbus_are_refused() {
        let h = |len: u16, proto: u16| {
            let ([l0, l1], [p0, p1]) = (len.to_be_bytes(), proto.to_be_bytes());
            header(&[0x12, 0x34, p0, p1, l0, l1, 7])
        };
        assert_eq!(
            h(6, 0),
            Some(Header {
                transaction: 0x1234,
                unit: 7,
                pdu_len: 5
            })
        );
        assert_eq!(h(257, 0).map(|h| h.pdu_len), Some(256));
        assert_eq!(h(258, 0), None);
        assert_eq!(h(65_535, 0), None);
        assert_eq!(h(1, 0), None, "no function code");
        assert_eq!(h(6, 1), None, "not Modbus");
    }

    #[test]
    fn malformed_pdus_get_01_or_03() {
        use ExceptionCode::{IllegalDataValue as V, IllegalFunction as F};
        assert_eq!(
            request(&[4, 0, 2, 0, 3]),
            Ok(Request::ReadInputRegisters(2, 3))
        );
        assert_eq!(request(&[4, 0, 2, 0]), Err(V), "truncated");
        assert_eq!(request(&[3, 0, 2, 0, 3, 9]), Err(V), "a trailing byte");
        assert_eq!(request(&[6, 0, 23, 0]), Err(V));
        assert_eq!(request(&[0x83, 0, 0, 0, 1]), Err(F));
        assert_eq!(request(&[0xFF]), Err(F));
        assert_eq!(request(&[0x01, 0, 0, 0, 1]), Err(F));
        let fc16 = |n: u16, count: u8, values: usize| {
            let mut p = vec![0x10, 0, 23];
            p.extend(n.to_be_bytes());
            p.push(count);
            p.extend(std::iter::repeat_n(0, values));
            request(&p)
        };
        assert_eq!(
            fc16(1, 2, 2),
            Ok(Request::WriteMultipleRegisters(23, Cow::Owned(vec![0])))
        );
        assert_eq!(fc16(123, 246, 246).map(|_| ()), Ok(()));
        assert_eq!(fc16(124, 248, 248), Err(V), "quantity 124");
        assert_eq!(fc16(0, 0, 0), Err(V));
        assert_eq!(fc16(2, 4, 2), Err(V), "values missing");
        assert_eq!(fc16(1, 2, 3), Err(V), "a trailing byte");
        assert_eq!(request(&[0x10, 0, 23, 0]), Err(V));
    }

    #[test]
    fn answers_are_encoded() {
        assert_eq!(
            response(4, Ok(Response::ReadInputRegisters(vec![0x0102, 0xA0B0]))),
            [4, 4, 1, 2, 0xA0, 0xB0]
        );
        assert_eq!(
            response(0x10, Ok(Response::WriteMultipleRegisters(23, 1))),
            [0x10, 0, 23, 0, 1]
        );
        assert_eq!(
            response(0x81, Err(ExceptionCode::IllegalFunction)),
            [0x81, 1]
        );
        assert_eq!(
            response(3, Err(ExceptionCode::GatewayPathUnavailable)),
            [0x83, 0x0A]
        );
        assert_eq!(
            frame(0x1234, 9, &[0x83, 2]),
            [0x12, 0x34, 0, 0, 0, 3, 9, 0x83, 2]
        );
    }
}
