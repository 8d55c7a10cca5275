//! What the board runs the node on, as pure numbers and types the board
//! binary and the virtual node share: boot and what survives a reset
//! ([`boot`]), when `Hello` and the frames run ([`schedule`]), the
//! clock across the timer's wrap ([`uptime`]), when the external clock is
//! tried again ([`clock_retry`]), the watchdog's timing ([`watchdog`]), the link's baud rates and RS-485
//! turn-taking ([`field_link`]), the worst time to answer a command
//! ([`reply_time`]), the flash's partitions for the bootloader, the store
//! and the update's slots ([`flash_layout`]).

pub mod boot;
pub mod clock_retry;
pub mod field_link;
pub mod flash_layout;
pub mod reply_time;
pub mod schedule;
pub mod uptime;
pub mod watchdog;
