//! The link protocol on the board's two transports, USB CDC-ACM and
//! USART1. Each task owns a `Port` (its own frame decoder) and hands the
//! bytes to the one shared server; the server's answers go back on the
//! transport they came from; a USB disconnect ends an injection the host
//! started on it (the UART has no connection to lose: the injection's
//! lease ends it). The server itself is transport-agnostic
//! (trueaxis_app::server): these tasks only move bytes.

use embassy_stm32::usart::BufferedUart;
use embassy_sync::blocking_mutex::raw::ThreadModeRawMutex;
use embassy_sync::mutex::Mutex;
use embassy_time::Instant;
use embassy_usb::class::cdc_acm::{CdcAcmClass, State};
use embassy_usb::{Builder, UsbDevice};
use embedded_io_async::{Read, Write};
use heapless::Vec;
use static_cell::StaticCell;
use trueaxis_app::server::Port;
use trueaxis_protocol::MAX_FRAME_BYTES;

use crate::board::UsbDriver;
use crate::shared::{BoardServer, SharedEngine};

/// Responses to one read (a read may complete several requests).
type OutBuf = Vec<u8, { 3 * MAX_FRAME_BYTES }>;

/// Runs the server on `input`; returns the response bytes. A response
/// that does not fit is dropped — the host retries after its timeout.
async fn serve(
    server: &Mutex<ThreadModeRawMutex, BoardServer>,
    engine: &SharedEngine,
    port: &mut Port,
    input: &[u8],
) -> OutBuf {
    let mut out = OutBuf::new();
    let now_us = Instant::now().as_micros();
    server
        .lock()
        .await
        .handle_bytes(port, input, now_us, engine, |frame| {
            let _ = out.extend_from_slice(frame);
        });
    out
}

/// Builds the USB device with one CDC-ACM function.
pub fn usb(
    driver: UsbDriver,
) -> (
    UsbDevice<'static, UsbDriver>,
    CdcAcmClass<'static, UsbDriver>,
) {
    static CONFIG_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static BOS_DESC: StaticCell<[u8; 256]> = StaticCell::new();
    static CONTROL: StaticCell<[u8; 64]> = StaticCell::new();
    static STATE: StaticCell<State> = StaticCell::new();

    let mut config = embassy_usb::Config::new(0x1209, 0x7a11);
    config.manufacturer = Some("trueaxis");
    config.product = Some("trueaxis compensation board");
    config.serial_number = Some("0001");
    let mut builder = Builder::new(
        driver,
        config,
        CONFIG_DESC.init([0; 256]),
        BOS_DESC.init([0; 256]),
        &mut [],
        CONTROL.init([0; 64]),
    );
    let class = CdcAcmClass::new(&mut builder, STATE.init(State::new()), 64);
    (builder.build(), class)
}

#[embassy_executor::task]
pub async fn usb_device(mut device: UsbDevice<'static, UsbDriver>) {
    device.run().await
}

#[embassy_executor::task]
pub async fn usb_link(
    mut class: CdcAcmClass<'static, UsbDriver>,
    server: &'static Mutex<ThreadModeRawMutex, BoardServer>,
    engine: &'static SharedEngine,
) {
    let mut port = Port::new();
    let mut buf = [0u8; 64];
    loop {
        class.wait_connection().await;
        port.reset();
        'connected: loop {
            let Ok(n) = class.read_packet(&mut buf).await else {
                break 'connected;
            };
            let out = serve(server, engine, &mut port, &buf[..n]).await;
            for packet in out.chunks(64) {
                if class.write_packet(packet).await.is_err() {
                    break 'connected;
                }
            }
            // A full last packet needs a zero-length one to end the
            // transfer on the host side.
            if !out.is_empty() && out.len() % 64 == 0 && class.write_packet(&[]).await.is_err() {
                break 'connected;
            }
        }
        // The host went (port closed, cable pulled): an injection it
        // started ends with it instead of steering the correction on.
        server.lock().await.port_closed(&mut port, engine);
    }
}

#[embassy_executor::task]
pub async fn uart_link(
    mut uart: BufferedUart<'static>,
    server: &'static Mutex<ThreadModeRawMutex, BoardServer>,
    engine: &'static SharedEngine,
) {
    let mut port = Port::new();
    let mut buf = [0u8; 64];
    loop {
        match uart.read(&mut buf).await {
            Ok(n) => {
                let out = serve(server, engine, &mut port, &buf[..n]).await;
                let _ = uart.write_all(&out).await;
            }
            // Framing/noise/overrun errors: drop the partial frame, the
            // host retries.
            Err(_) => port.reset(),
        }
    }
}
