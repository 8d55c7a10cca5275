//! One row of the response table ([`TableEntry`]): the fixed-point packing
//! the generated `table.rs` is written in. A leaf: the table and the filter
//! read it, it reads nothing of the estimator.

/// One row of the response table: mean and spread of (I1, I2) at one
/// thickness of one medium, in fixed point (10 bytes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TableEntry {
    /// Mean μ of I1, I2, nA.
    pub mu_na: [u16; 2],
    /// Standard deviation of I1, I2, nA.
    pub sd_na: [u16; 2],
    /// Correlation of I1 and I2, × 32767.
    pub rho_q15: i16,
}

impl TableEntry {
    /// A row (the generated table is written with this).
    pub const fn new(mu1_na: u16, mu2_na: u16, sd1_na: u16, sd2_na: u16, rho_q15: i16) -> Self {
        TableEntry {
            mu_na: [mu1_na, mu2_na],
            sd_na: [sd1_na, sd2_na],
            rho_q15,
        }
    }
}
