//! The embassy application for the NUCLEO-F446RE. Only this file and the
//! board module touch the HAL.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]

#[cfg(target_os = "none")]
mod app {
    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_time::Timer;
    use panic_probe as _;

    #[embassy_executor::main]
    async fn main(_spawner: Spawner) {
        let _p = embassy_stm32::init(Default::default());
        loop {
            defmt::info!("tick");
            Timer::after_secs(1).await;
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("fois-node is firmware: build it with `cargo fw` (thumbv7em-none-eabihf)");
}
