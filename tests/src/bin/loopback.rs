//! Transport check of the end-to-end setup, below the link protocol: echoes
//! every byte USART1 receives, under embassy-executor with the SysTick time
//! driver. xtask connects to QEMU's TCP serial, sends a seeded pseudo-random
//! byte stream and requires it back unchanged; The image first sends `0xFF 'R'` (ready), and when xtask sends `0xFF 'Q'` and
//! the image exits 0 — so a failure here points at QEMU, the USART driver or
//! the executor, not at the application.
#![no_std]
#![no_main]

use embassy_time::{Duration, Instant, Timer};
use trueaxis_qemu::{executor::WfiExecutor, time_driver, usart::Usart1};

#[embassy_executor::task]
async fn echo(mut uart: Usart1) {
    let mut buf = [0u8; 64];
    let mut echoed: u32 = 0;
    let mut prev = 0u8;
    loop {
        let n = uart.read(&mut buf).await;
        uart.write(&buf[..n]);
        for &b in &buf[..n] {
            // The quit sequence never occurs in the stream (xtask's stream
            // contains no 0xFF).
            if prev == 0xFF && b == b'Q' {
                defmt::info!("loopback: echoed {} bytes, quitting", echoed);
                trueaxis_qemu::exit(0);
            }
            prev = b;
            echoed += 1;
        }
    }
}

#[embassy_executor::task]
async fn heartbeat() {
    // Exercises the time driver while the echo runs: every sleep must last
    // at least what was asked (a driver that wakes early fails the run).
    loop {
        let t0 = Instant::now();
        Timer::after(Duration::from_millis(5)).await;
        let slept = t0.elapsed();
        if slept < Duration::from_millis(5) {
            defmt::error!("timer woke early: {} us", slept.as_micros());
            trueaxis_qemu::exit(1);
        }
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let core = cortex_m::Peripherals::take().expect("first take");
    time_driver::start(core.SYST);
    let mut uart = Usart1::new();
    // QEMU drops what arrives before the USART is enabled, so tell the host
    // when it may start sending.
    uart.write(&[0xFF, b'R']);
    defmt::info!("loopback: ready");
    let executor = cortex_m::singleton!(: WfiExecutor = WfiExecutor::new()).expect("once");
    executor.run(|spawner| {
        spawner.spawn(echo(uart).expect("echo task spawns once"));
        spawner.spawn(heartbeat().expect("heartbeat task spawns once"));
    })
}
