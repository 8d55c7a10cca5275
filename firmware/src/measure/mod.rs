//! From ADC codes to physical values: the photocurrents by synchronous
//! detection ([`photocurrent`]), the air temperature from the NTC divider
//! ([`ntc`]), V_DDA and the die temperature from the factory calibration
//! ([`vref`]).

pub mod ntc;
pub mod photocurrent;
pub mod vref;
