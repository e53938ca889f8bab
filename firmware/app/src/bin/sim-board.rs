//! The simulated board on a TCP port, for trying the host tool by hand:
//! `cargo run -p trueaxis-app --features std --target x86_64-unknown-linux-gnu
//! --bin sim-board -- 127.0.0.1:7878`, then
//! `trueaxis status --port tcp://127.0.0.1:7878`. Flash is RAM: it starts
//! empty every run.

use std::net::TcpListener;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

fn main() -> std::io::Result<()> {
    let addr = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "127.0.0.1:7878".into());
    let listener = TcpListener::bind(&addr)?;
    eprintln!("sim-board listening on tcp://{}", listener.local_addr()?);
    trueaxis_app::sim::SimBoard::new().serve(listener, Arc::new(AtomicBool::new(false)));
    Ok(())
}
