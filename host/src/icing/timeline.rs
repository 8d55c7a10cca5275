//! The thickness series decimated for the timeline figure: buckets of equal
//! width, at most [`MAX_BUCKETS`]; when there would be more, neighbours merge
//! and the width doubles. A year at 1 Hz ends in buckets of a few hours,
//! whatever the length, in bounded memory.

/// Buckets kept at most.
pub const MAX_BUCKETS: usize = 4096;
/// The first bucket width, ms.
pub const FIRST_WIDTH_MS: u64 = 10_000;

/// One bucket: the mean thickness and mean σ of its samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bucket {
    /// Its index: it starts at origin + index × width.
    pub index: u64,
    /// Samples in it.
    pub n: u64,
    sum_mm: f64,
    sum_sigma_mm: f64,
}

impl Bucket {
    /// The mean thickness, mm.
    pub fn mean_mm(&self) -> f64 {
        self.sum_mm / self.n.max(1) as f64
    }

    /// The mean standard deviation, mm.
    pub fn sigma_mm(&self) -> f64 {
        self.sum_sigma_mm / self.n.max(1) as f64
    }
}

/// The decimated series.
#[derive(Debug, Clone, Default)]
pub struct Timeline {
    origin_ms: Option<u64>,
    width_ms: u64,
    buckets: Vec<Bucket>,
}

impl Timeline {
    /// Add a sample (in time order).
    pub fn push(&mut self, t_ms: u64, thickness_mm: f64, sigma_mm: f64) {
        if self.width_ms == 0 {
            self.width_ms = FIRST_WIDTH_MS;
        }
        let origin = *self.origin_ms.get_or_insert(t_ms);
        let index = t_ms.saturating_sub(origin) / self.width_ms;
        match self.buckets.last_mut() {
            Some(b) if b.index == index => {
                b.n += 1;
                b.sum_mm += thickness_mm;
                b.sum_sigma_mm += sigma_mm;
            }
            _ => {
                self.buckets.push(Bucket {
                    index,
                    n: 1,
                    sum_mm: thickness_mm,
                    sum_sigma_mm: sigma_mm,
                });
                if self.buckets.len() > MAX_BUCKETS {
                    self.coarsen();
                }
            }
        }
    }

    fn coarsen(&mut self) {
        self.width_ms *= 2;
        let mut merged: Vec<Bucket> = Vec::with_capacity(self.buckets.len() / 2 + 1);
        for b in self.buckets.drain(..) {
            let index = b.index / 2;
            match merged.last_mut() {
                Some(m) if m.index == index => {
                    m.n += b.n;
                    m.sum_mm += b.sum_mm;
                    m.sum_sigma_mm += b.sum_sigma_mm;
                }
                _ => merged.push(Bucket { index, ..b }),
            }
        }
        self.buckets = merged;
    }

    /// Nothing more comes (kept for symmetry with the other passes).
    pub fn finish(&mut self) {
        self.buckets.shrink_to_fit();
    }

    /// The buckets in time order.
    pub fn buckets(&self) -> &[Bucket] {
        &self.buckets
    }

    /// A bucket's start, Unix ms.
    pub fn start_ms(&self, b: &Bucket) -> u64 {
        self.origin_ms.unwrap_or(0) + b.index * self.width_ms
    }

    /// The bucket width, ms.
    pub fn width_ms(&self) -> u64 {
        self.width_ms
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_year_at_1_hz_stays_within_the_bucket_bound() {
        let mut t = Timeline::default();
        let n = 365 * 86_400u64;
        for s in (0..n).step_by(7) {
            t.push(s * 1000, (s % 1000) as f64 / 100.0, 0.5);
        }
        assert!(t.buckets().len() <= MAX_BUCKETS);
        assert!(t.buckets().len() > MAX_BUCKETS / 2);
        // 31 536 000 s over at most 4096 buckets: 10 s × 2^k ≥ 7 699 s.
        assert_eq!(t.width_ms(), 10_240_000);
        let total: u64 = t.buckets().iter().map(|b| b.n).sum();
        assert_eq!(total, n.div_ceil(7));
        assert!((t.buckets()[0].sigma_mm() - 0.5).abs() < 1e-12);
    }
}
