//! Synthetic monitor logs of known icing, for the benchmark (a year at
//! 1 Hz, 31.5 M rows, generated on the fly: no 4 GB file) and the tests.
//! Each kind of day is formatted once as a template; every day after is
//! the template with its date and Unix time patched in (fixed-width
//! fields), so making the text costs little beside reading it.

use std::io::Read;

use fois_link::log_row::HEADER;
use fois_link::timefmt::iso_utc;

/// One day, ms.
pub const DAY_MS: u64 = 86_400_000;
/// The first day of a synthetic log: 2026-01-01 00:00 UTC.
pub const BASE_MS: u64 = 1_767_225_600_000;

/// The node's icing-rate columns (appended when the header has none yet).
pub const RATE_COLUMNS: [&str; 3] = [
    "est_rate_mm_per_h",
    "est_rate_sigma_mm_per_h",
    "est_accreting",
];

/// An icing day: rime grows at a constant rate from `start_s` for
/// `grow_s`, stays, and is shed (the face dry) at `shed_s` (seconds after
/// midnight UTC).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcingDay {
    /// Growth starts, s after midnight.
    pub start_s: u32,
    /// Growth lasts, s.
    pub grow_s: u32,
    /// Shedding, s after midnight.
    pub shed_s: u32,
    /// Growth rate, mm/h.
    pub rate_mm_per_h: f64,
}

/// The icing day of the benchmark and tests: 2 mm/h of rime from 06:00
/// for 3 h (6 mm), shed at 18:00. Meteorological icing 3 h; instrumental
/// from 0.3 mm (06:09) to 18:00, 11.85 h.
pub const ICING_DAY: IcingDay = IcingDay {
    start_s: 6 * 3600,
    grow_s: 3 * 3600,
    shed_s: 18 * 3600,
    rate_mm_per_h: 2.0,
};

/// A day formatted once: its text and where each row's time fields are.
#[derive(Debug, Clone)]
struct Template {
    bytes: Vec<u8>,
    iso_at: Vec<usize>,
    ms_at: Vec<usize>,
}

/// The header of a synthetic log (with or without the rate columns).
pub fn header(with_rate: bool) -> String {
    let mut h = HEADER.to_string();
    for c in RATE_COLUMNS {
        let present = HEADER.split(',').any(|x| x == c);
        if !present && with_rate {
            h.push(',');
            h.push_str(c);
        }
        if present && !with_rate {
            h = h
                .split(',')
                .filter(|x| *x != c)
                .collect::<Vec<_>>()
                .join(",");
        }
    }
    h
}

fn template(icing: Option<IcingDay>, period_s: u32, with_rate: bool) -> Template {
    let cols: Vec<String> = header(with_rate).split(',').map(str::to_string).collect();
    let mut t = Template {
        bytes: Vec::new(),
        iso_at: Vec::new(),
        ms_at: Vec::new(),
    };
    for (seq, s) in (0..86_400u32).step_by(period_s.max(1) as usize).enumerate() {
        let ms = BASE_MS + u64::from(s) * 1000;
        let (d, growing) = match icing {
            Some(i) if s >= i.start_s && s < i.shed_s => {
                let g = (s - i.start_s).min(i.grow_s);
                (
                    i.rate_mm_per_h * f64::from(g) / 3600.0,
                    s < i.start_s + i.grow_s,
                )
            }
            _ => (0.0, false),
        };
        let ice = d > 0.0;
        for (k, c) in cols.iter().enumerate() {
            if k > 0 {
                t.bytes.push(b',');
            }
            let v = match c.as_str() {
                "host_time_utc" => {
                    t.iso_at.push(t.bytes.len());
                    iso_utc(ms)
                }
                "host_unix_ms" => {
                    t.ms_at.push(t.bytes.len());
                    ms.to_string()
                }
                "kind" => "measurement".into(),
                "seq" => seq.to_string(),
                "uptime_ms" => (u64::from(s) * 1000).to_string(),
                "i1_ua" => format!("{:.3}", 25.0 + 2.0 * d),
                "i2_ua" => format!("{:.3}", 8.0 + 0.5 * d),
                "ambient1_ua" => "1.200".into(),
                "ambient2_ua" => "0.900".into(),
                "temperature_c" => "-5.12".into(),
                "vdda_mv" => "3300".into(),
                "state" => if ice { "Ice" } else { "Dry" }.into(),
                "alarm" => u8::from(ice).to_string(),
                "valid" => "1".into(),
                "flags" => if ice { "64" } else { "0" }.into(),
                "est_thickness_mm" => format!("{d:.3}"),
                "est_sigma_mm" => format!("{:.3}", 0.1 + 0.05 * d),
                "est_kind" => if ice { "rime" } else { "dry" }.into(),
                "est_p" => "0.950".into(),
                "est_gain" => "1.0000".into(),
                "est_gain_sigma" => "0.0500".into(),
                "est_rate_mm_per_h" => match icing {
                    Some(i) if growing => format!("{:.3}", i.rate_mm_per_h),
                    _ => "0.000".into(),
                },
                "est_rate_sigma_mm_per_h" => "0.500".into(),
                "est_accreting" => if growing { "0.970" } else { "0.020" }.into(),
                _ => String::new(),
            };
            t.bytes.extend_from_slice(v.as_bytes());
        }
        t.bytes.push(b'\n');
    }
    t
}

/// Write `v` as exactly `out.len()` decimal digits.
fn put_digits(out: &mut [u8], mut v: u64) {
    for b in out.iter_mut().rev() {
        *b = b'0' + (v % 10) as u8;
        v /= 10;
    }
}

/// A synthetic log as a byte stream: the header, then `days` days from
/// [`BASE_MS`], every `icing_every`-th day (day 0 first) an
/// [`ICING_DAY`], the others dry.
pub struct SyntheticLog {
    pending: Vec<u8>,
    pos: usize,
    dry: Template,
    icing: Template,
    day: u64,
    days: u64,
    icing_every: u64,
    /// Rows made so far.
    pub rows: u64,
}

impl SyntheticLog {
    /// `days` days, one row per `period_s`, an icing day every
    /// `icing_every` days, with or without the node's rate columns.
    pub fn new(days: u64, period_s: u32, icing_every: u64, with_rate: bool) -> SyntheticLog {
        SyntheticLog {
            pending: format!("{}\n", header(with_rate)).into_bytes(),
            pos: 0,
            dry: template(None, period_s, with_rate),
            icing: template(Some(ICING_DAY), period_s, with_rate),
            day: 0,
            days,
            icing_every: icing_every.max(1),
            rows: 0,
        }
    }

    /// The icing days among the first `days`.
    pub fn icing_days(days: u64, icing_every: u64) -> u64 {
        days.div_ceil(icing_every.max(1))
    }

    fn next_day(&mut self) {
        let t = if self.day.is_multiple_of(self.icing_every) {
            &self.icing
        } else {
            &self.dry
        };
        self.pending.clear();
        self.pending.extend_from_slice(&t.bytes);
        self.pos = 0;
        let shift = self.day * DAY_MS;
        let date = iso_utc(BASE_MS + shift);
        let date = &date.as_bytes()[..10];
        for (&iso, &ms) in t.iso_at.iter().zip(&t.ms_at) {
            self.pending[iso..iso + 10].copy_from_slice(date);
            let mut v = 0u64;
            for &b in &t.bytes[ms..ms + 13] {
                v = v * 10 + u64::from(b - b'0');
            }
            put_digits(&mut self.pending[ms..ms + 13], v + shift);
        }
        self.rows += t.ms_at.len() as u64;
        self.day += 1;
    }
}

impl Read for SyntheticLog {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.pos >= self.pending.len() {
            if self.day >= self.days {
                return Ok(0);
            }
            self.next_day();
        }
        let n = buf.len().min(self.pending.len() - self.pos);
        buf[..n].copy_from_slice(&self.pending[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

/// The whole synthetic log as bytes (tests: a few days).
pub fn synthetic_bytes(days: u64, period_s: u32, icing_every: u64, with_rate: bool) -> Vec<u8> {
    let mut v = Vec::new();
    // Reading from memory cannot fail.
    let _ = SyntheticLog::new(days, period_s, icing_every, with_rate).read_to_end(&mut v);
    v
}
