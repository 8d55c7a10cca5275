//! FOIS node logic, free of any HAL: measurement maths, the ice rule, config
//! handling and command dispatch. Runs on the board, in host tests, in the
//! host's virtual node and in the hardware-in-loop suite.
#![cfg_attr(not(test), no_std)]
