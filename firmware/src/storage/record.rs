//! The persisted record: config, dark baseline, the optical gain (the
//! learned estimate and the last calibration) and the host link's settings
//! (framed or Modbus RTU), with a version and a CRC.
//!
//! ```text
//! | magic "FOIS" 4 B | version u16 LE | length u16 LE | postcard(Record) | CRC-32 u32 LE |
//! ```
//! The CRC (CRC-32/ISO-HDLC, the `crc` crate) covers everything before it.
//! Erased flash (0xFF) or an empty store is *empty*: defaults, no fault. A bad
//! magic, version, length, CRC, postcard body or a config that fails
//! [`Config::validate`] is *corrupt*: defaults and `CONFIG_DEFAULTED`.

use fois_protocol::framing::CRC;
use fois_protocol::{Baseline, Config, ConfigV1, GainEstimate, LinkSettings};
use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

/// First four bytes of a record.
pub const MAGIC: [u8; 4] = *b"FOIS";
/// Record layout version; bump when [`Record`] changes shape. A record of
/// a version this firmware knows ([`RecordV1`], [`RecordV2`], [`RecordV3`])
/// is read and upgraded; any other is refused (defaults + fault), never
/// misread.
pub const RECORD_VERSION: u16 = 4;
const HEADER: usize = 8;
const CRC_LEN: usize = 4;
/// The largest record, bytes.
pub const MAX_RECORD: usize = HEADER + Record::POSTCARD_MAX_SIZE + CRC_LEN;

/// What is kept across resets.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
pub struct Record {
    /// The config in force.
    pub config: Config,
    /// The dark baseline, once calibrated.
    pub baseline: Option<Baseline>,
    /// Layout 3: the optical gain the estimator learned (at the temperature
    /// model's reference temperature; σ absolute), the prior after a reset.
    pub gain: Option<GainEstimate>,
    /// Layout 3: the last gain calibration against a target (same form);
    /// a dark calibration returns the learned gain to it.
    pub gain_calibration: Option<GainEstimate>,
    /// Layout 4: the host link's protocol (framed or Modbus RTU) and its
    /// Modbus address and parity.
    pub link: LinkSettings,
}

/// The record of layout version 3 (firmware of protocol versions 3 and 4):
/// config, baseline and the gain. Read and upgraded (the framed link).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordV3 {
    /// The config in force.
    pub config: Config,
    /// The dark baseline, once calibrated.
    pub baseline: Option<Baseline>,
    /// The learned gain.
    pub gain: Option<GainEstimate>,
    /// The last gain calibration.
    pub gain_calibration: Option<GainEstimate>,
}

/// The record of layout version 2 (firmware of protocol version 3 before
/// the gain was kept): config and baseline. Read and upgraded (no gain).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordV2 {
    /// The config in force.
    pub config: Config,
    /// The dark baseline, once calibrated.
    pub baseline: Option<Baseline>,
}

/// The record of layout version 1 (firmware of protocol versions 1 and 2):
/// the config in its version-1 shape. Read at boot and upgraded (the newer
/// config fields at their defaults), so a firmware update keeps the
/// node's settings and dark baseline.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordV1 {
    /// The config in force.
    pub config: ConfigV1,
    /// The dark baseline, once calibrated.
    pub baseline: Option<Baseline>,
}

/// Why a stored record was not used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadError {
    /// Nothing was ever stored (erased or empty): defaults, not a fault.
    Empty,
    /// A record of another layout version.
    OldVersion,
    /// Bad magic, length, CRC, body, or a config that fails validation.
    Corrupt,
}

/// Encode `record` into `out`; returns the record's length.
pub fn encode(record: &Record, out: &mut [u8; MAX_RECORD]) -> usize {
    let body_len = match out.get_mut(HEADER..MAX_RECORD - CRC_LEN) {
        Some(body) => match postcard::to_slice(record, body) {
            Ok(b) => b.len(),
            Err(_) => return 0,
        },
        None => return 0,
    };
    out[..4].copy_from_slice(&MAGIC);
    out[4..6].copy_from_slice(&RECORD_VERSION.to_le_bytes());
    out[6..8].copy_from_slice(&(body_len as u16).to_le_bytes());
    let end = HEADER + body_len;
    let crc = CRC.checksum(&out[..end]).to_le_bytes();
    out[end..end + CRC_LEN].copy_from_slice(&crc);
    end + CRC_LEN
}

/// Decode a record from stored bytes (which may run on past its end).
pub fn decode(bytes: &[u8]) -> Result<Record, LoadError> {
    if bytes.iter().all(|&b| b == 0xFF) {
        return Err(LoadError::Empty); // also an empty slice
    }
    let header = bytes.get(..HEADER).ok_or(LoadError::Corrupt)?;
    if header.get(..4) != Some(&MAGIC[..]) {
        return Err(LoadError::Corrupt);
    }
    let version = u16::from_le_bytes([header[4], header[5]]);
    let body_len = usize::from(u16::from_le_bytes([header[6], header[7]]));
    let end = HEADER.checked_add(body_len).ok_or(LoadError::Corrupt)?;
    let signed = bytes.get(..end).ok_or(LoadError::Corrupt)?;
    let crc_bytes = bytes.get(end..end + CRC_LEN).ok_or(LoadError::Corrupt)?;
    let stored_crc = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    if CRC.checksum(signed) != stored_crc {
        return Err(LoadError::Corrupt);
    }
    let body = signed.get(HEADER..).ok_or(LoadError::Corrupt)?;
    let record: Record = match version {
        RECORD_VERSION => match postcard::take_from_bytes(body) {
            Ok((r, [])) => r,
            _ => return Err(LoadError::Corrupt),
        },
        3 => match postcard::take_from_bytes::<RecordV3>(body) {
            Ok((r, [])) => Record {
                config: r.config,
                baseline: r.baseline,
                gain: r.gain,
                gain_calibration: r.gain_calibration,
                link: LinkSettings::default(),
            },
            _ => return Err(LoadError::Corrupt),
        },
        2 => match postcard::take_from_bytes::<RecordV2>(body) {
            Ok((r, [])) => Record {
                config: r.config,
                baseline: r.baseline,
                gain: None,
                gain_calibration: None,
                link: LinkSettings::default(),
            },
            _ => return Err(LoadError::Corrupt),
        },
        1 => match postcard::take_from_bytes::<RecordV1>(body) {
            Ok((r, [])) => Record {
                config: Config::from(r.config),
                baseline: r.baseline,
                gain: None,
                gain_calibration: None,
                link: LinkSettings::default(),
            },
            _ => return Err(LoadError::Corrupt),
        },
        _ => return Err(LoadError::OldVersion),
    };
    record.config.validate().map_err(|_| LoadError::Corrupt)?;
    record.link.validate().map_err(|_| LoadError::Corrupt)?;
    Ok(record)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of layout `version` with this body, as the firmware of that
    /// layout wrote it (erased flash after it); and where its CRC starts.
    fn framed(version: u16, body: &impl Serialize) -> ([u8; 128], usize) {
        let mut buf = [0xFFu8; 128];
        let body_len = postcard::to_slice(body, &mut buf[HEADER..]).unwrap().len();
        buf[..4].copy_from_slice(&MAGIC);
        buf[4..6].copy_from_slice(&version.to_le_bytes());
        buf[6..8].copy_from_slice(&(body_len as u16).to_le_bytes());
        let end = HEADER + body_len;
        let crc = CRC.checksum(&buf[..end]).to_le_bytes();
        buf[end..end + CRC_LEN].copy_from_slice(&crc);
        (buf, end)
    }

    fn sample() -> Record {
        Record {
            config: Config {
                onset_rise_na: 1_234,
                ..Config::default()
            },
            baseline: Some(Baseline {
                i1_na: -40,
                i2_na: 12,
            }),
            gain: Some(GainEstimate {
                gain_ppm: 870_000,
                sigma_ppm: 26_100,
            }),
            gain_calibration: Some(GainEstimate {
                gain_ppm: 850_000,
                sigma_ppm: 17_000,
            }),
            link: LinkSettings::default(),
        }
    }

    #[test]
    fn round_trip_with_trailing_erased_flash() {
        let mut buf = [0u8; MAX_RECORD];
        let n = encode(&sample(), &mut buf);
        assert!(n > HEADER + CRC_LEN && n <= MAX_RECORD);
        let mut flash = [0xFFu8; 256];
        flash[..n].copy_from_slice(&buf[..n]);
        assert_eq!(decode(&flash), Ok(sample()));
        assert_eq!(decode(&buf[..n]), Ok(sample()));
    }

    #[test]
    fn empty_corrupt_and_old() {
        assert_eq!(decode(&[]), Err(LoadError::Empty));
        assert_eq!(decode(&[0xFF; 64]), Err(LoadError::Empty));
        let mut buf = [0u8; MAX_RECORD];
        let n = encode(&sample(), &mut buf);
        // Every single bit flip is caught.
        for i in 0..n {
            for bit in 0..8 {
                let mut b = buf;
                b[i] ^= 1 << bit;
                assert!(decode(&b[..n]).is_err(), "flip {i}.{bit} accepted");
            }
        }
        // Truncated.
        assert_eq!(decode(&buf[..n - 1]), Err(LoadError::Corrupt));
        // Old version with a valid CRC.
        let mut old = buf;
        old[4..6].copy_from_slice(&0u16.to_le_bytes());
        let crc = CRC.checksum(&old[..n - 4]).to_le_bytes();
        old[n - 4..n].copy_from_slice(&crc);
        assert_eq!(decode(&old[..n]), Err(LoadError::OldVersion));
        // A well-formed record whose config breaks the rule is corrupt.
        let bad = Record {
            config: Config {
                clear_rise_na: 5_000,
                onset_rise_na: 1_000,
                ..Config::default()
            },
            baseline: None,
            gain: None,
            gain_calibration: None,
            link: LinkSettings::default(),
        };
        let n = encode(&bad, &mut buf);
        assert_eq!(decode(&buf[..n]), Err(LoadError::Corrupt));
    }

    /// A record written by the firmware of protocol versions 1–2 (layout
    /// version 1, the version-1 config) is read and upgraded: settings and
    /// baseline survive a firmware update.
    #[test]
    fn layout_version_1_is_upgraded() {
        let old = RecordV1 {
            config: ConfigV1 {
                onset_rise_na: 1_500,
                ..ConfigV1::from(&Config::default())
            },
            baseline: Some(Baseline {
                i1_na: 310,
                i2_na: -7,
            }),
        };
        let (mut buf, end) = framed(1, &old);
        // The bytes of a version-1 record, as that firmware wrote them.
        let golden: [u8; 35] = [
            0x46, 0x4f, 0x49, 0x53, 0x01, 0x00, 0x17, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e,
            0x90, 0x4e, 0xdc, 0x0b, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0x01,
            0xec, 0x04, 0x0d, 0x3b, 0xf4, 0xd5, 0xa0,
        ];
        assert_eq!(buf[..end + CRC_LEN], golden);
        let read = decode(&buf).unwrap();
        assert_eq!(read.config.onset_rise_na, 1_500);
        assert_eq!(read.config.gain_tempco_sd_ppm_per_k, 4_000);
        assert_eq!(read.config.gain_low_permille, 600);
        assert_eq!(read.baseline, old.baseline);
        // A version-1 record's body does not pass for a newer one.
        buf[4..6].copy_from_slice(&RECORD_VERSION.to_le_bytes());
        let crc = CRC.checksum(&buf[..end]).to_le_bytes();
        buf[end..end + CRC_LEN].copy_from_slice(&crc);
        assert_eq!(decode(&buf), Err(LoadError::Corrupt));
    }

    /// A record written before the gain was kept (layout version 2: the
    /// version-3 config and the baseline) is read and upgraded with no gain:
    /// the estimator starts from the unknown prior.
    #[test]
    fn layout_version_2_is_upgraded() {
        let old = RecordV2 {
            config: Config {
                onset_rise_na: 1_500,
                gain_tempco_ppm_per_k: -4_000,
                ..Config::default()
            },
            baseline: Some(Baseline {
                i1_na: 310,
                i2_na: -7,
            }),
        };
        let (buf, end) = framed(2, &old);
        // The bytes of a version-2 record, as that firmware wrote them.
        let golden: &[u8] = &GOLDEN_V2;
        assert_eq!(&buf[..end + CRC_LEN], golden);
        let read = decode(&buf).unwrap();
        assert_eq!(read.config, old.config);
        assert_eq!(read.baseline, old.baseline);
        assert_eq!((read.gain, read.gain_calibration), (None, None));
    }

    /// A record of layout 3 (config, baseline, learned and calibrated gain,
    /// protocol 3 and 4 firmware) is read and upgraded: the link stays
    /// framed.
    #[test]
    fn layout_version_3_is_upgraded() {
        let gain = GainEstimate {
            gain_ppm: 1_050_000,
            sigma_ppm: 20_000,
        };
        let old = RecordV3 {
            config: Config::default(),
            baseline: Some(Baseline {
                i1_na: 310,
                i2_na: -7,
            }),
            gain: Some(gain),
            gain_calibration: None,
        };
        let (buf, end) = framed(3, &old);
        // The bytes of a version-3 record, as that firmware wrote them.
        let golden: &[u8] = &GOLDEN_V3;
        assert_eq!(&buf[..end + CRC_LEN], golden);
        let read = decode(&buf).unwrap();
        assert_eq!(read.config, old.config);
        assert_eq!(read.baseline, old.baseline);
        assert_eq!((read.gain, read.gain_calibration), (Some(gain), None));
        assert_eq!(read.link, LinkSettings::default());
    }

    /// Layout 4 keeps the link settings; an address outside 1–247 is a
    /// corrupt record (defaults and the fault), never a node that cannot be
    /// addressed.
    #[test]
    fn layout_version_4_keeps_the_link_and_refuses_a_bad_address() {
        let mut r = sample();
        r.link = LinkSettings {
            protocol: fois_protocol::LinkProtocol::ModbusRtu,
            modbus_address: 17,
            parity: fois_protocol::Parity::None8N1,
        };
        let mut out = [0xFFu8; MAX_RECORD];
        let n = encode(&r, &mut out);
        assert_eq!(decode(&out[..n]), Ok(r.clone()));
        r.link.modbus_address = 0;
        let n = encode(&r, &mut out);
        assert_eq!(decode(&out[..n]), Err(LoadError::Corrupt));
    }

    const GOLDEN_V3: [u8; 50] = [
        0x46, 0x4f, 0x49, 0x53, 0x03, 0x00, 0x26, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e, 0x90,
        0x4e, 0xe8, 0x07, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0x00, 0xa0, 0x1f,
        0xd8, 0x04, 0xdc, 0x0b, 0x01, 0xec, 0x04, 0x0d, 0x01, 0x90, 0x8b, 0x40, 0xa0, 0x9c, 0x01,
        0x00, 0x96, 0x38, 0x2b, 0x2f,
    ];

    const GOLDEN_V2: [u8; 43] = [
        0x46, 0x4f, 0x49, 0x53, 0x02, 0x00, 0x1f, 0x00, 0x64, 0x08, 0xc8, 0x01, 0x90, 0x4e, 0x90,
        0x4e, 0xdc, 0x0b, 0x1e, 0xc8, 0x01, 0xac, 0x02, 0x64, 0xf4, 0x03, 0x01, 0xbf, 0x3e, 0xa0,
        0x1f, 0xd8, 0x04, 0xdc, 0x0b, 0x01, 0xec, 0x04, 0x0d, 0x79, 0x6b, 0x3d, 0x21,
    ];
}
