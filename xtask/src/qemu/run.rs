//! Running an image under `qemu-system-arm -M netduinoplus2 -icount
//! shift=0`: to completion with a wall-clock timeout (the semihosting exit
//! status is the verdict, `defmt-print` decodes the log), or kept running
//! with its serial port on a local TCP port for the link tests.

use std::io::Read;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use super::TIMEOUT;
use crate::Result;

/// Extra QEMU settings of one run.
#[derive(Debug, Default, Clone)]
pub(super) struct QemuOpts {
    /// `-serial` backend (USART1); `null` when not given.
    pub(super) serial: Option<String>,
    /// Wall-clock limit; [`TIMEOUT`] when not given.
    pub(super) timeout: Option<Duration>,
    /// The image prints plain text on semihosting stdout (tickbench), not
    /// defmt: no `defmt-print`.
    pub(super) plain: bool,
}

/// What one image printed and how it ended.
#[derive(Debug)]
pub(super) struct ImageRun {
    pub(super) status: ExitStatus,
    /// The decoded defmt log (defmt-print's output).
    pub(super) log: String,
    /// QEMU's stderr: the HardFault report, QEMU's own errors.
    pub(super) stderr: String,
}

/// Runs `elf` in QEMU with its semihosting output piped through
/// `defmt-print`, and waits for it to exit (or kills it at the timeout).
pub(super) fn run_image(elf: &Path, opts: &QemuOpts) -> Result<ImageRun> {
    start_image(elf, opts)?.wait()
}

/// An image running in QEMU, its log being decoded in the background.
pub(super) struct RunningImage {
    pub(super) elf: PathBuf,
    pub(super) qemu: std::process::Child,
    pub(super) printer: Option<std::process::Child>,
    pub(super) log_reader: thread::JoinHandle<String>,
    pub(super) err_reader: thread::JoinHandle<String>,
    pub(super) started: Instant,
    pub(super) limit: Duration,
}

/// Starts `elf` in QEMU (see [`run_image`]); the caller talks to it (TCP
/// serial) and then calls [`RunningImage::wait`].
pub(super) fn start_image(elf: &Path, opts: &QemuOpts) -> Result<RunningImage> {
    let elf_s = elf.to_string_lossy().into_owned();
    let serial = opts.serial.clone().unwrap_or_else(|| "null".into());
    let mut qemu = Command::new("qemu-system-arm")
        .args([
            "-M",
            "netduinoplus2",
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            &serial,
            "-semihosting-config",
            "enable=on,target=native",
            "-icount",
            "shift=0",
            "-kernel",
            &elf_s,
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm (cargo xtask setup): {e}"))?;
    let mut qemu_out = qemu.stdout.take().expect("stdout is piped");
    let mut qemu_err = qemu.stderr.take().expect("stderr is piped");
    let err_reader = thread::spawn(move || {
        let mut s = String::new();
        let _ = qemu_err.read_to_string(&mut s);
        s
    });
    if opts.plain {
        let log_reader = thread::spawn(move || {
            let mut s = String::new();
            let _ = qemu_out.read_to_string(&mut s);
            s
        });
        return Ok(RunningImage {
            elf: elf.to_path_buf(),
            qemu,
            printer: None,
            log_reader,
            err_reader,
            started: Instant::now(),
            limit: opts.timeout.unwrap_or(TIMEOUT),
        });
    }
    let printer = Command::new("defmt-print")
        .args(["-e", &elf_s, "stdin"])
        .stdin(Stdio::from(qemu_out))
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn();
    let mut printer = match printer {
        Ok(p) => p,
        Err(e) => {
            let _ = qemu.kill();
            let _ = qemu.wait();
            return Err(format!("cannot start defmt-print (cargo xtask setup): {e}"));
        }
    };
    let mut printer_out = printer.stdout.take().expect("stdout is piped");
    let log_reader = thread::spawn(move || {
        let mut s = String::new();
        let _ = printer_out.read_to_string(&mut s);
        s
    });
    Ok(RunningImage {
        elf: elf.to_path_buf(),
        qemu,
        printer: Some(printer),
        log_reader,
        err_reader,
        started: Instant::now(),
        limit: opts.timeout.unwrap_or(TIMEOUT),
    })
}

impl RunningImage {
    /// Waits for QEMU to exit; kills it when the time limit (counted from
    /// the start) runs out, which is an error.
    pub(super) fn wait(mut self) -> Result<ImageRun> {
        let status = loop {
            match self.qemu.try_wait() {
                Ok(Some(status)) => break Some(status),
                Ok(None) if self.started.elapsed() > self.limit => break None,
                Ok(None) => thread::sleep(Duration::from_millis(20)),
                Err(e) => {
                    self.kill();
                    return Err(format!("waiting for qemu: {e}"));
                }
            }
        };
        if status.is_none() {
            self.kill();
        }
        // QEMU's exit closes the pipe, so defmt-print ends by itself.
        if let Some(p) = self.printer.as_mut() {
            let _ = p.wait();
        }
        let log = self.log_reader.join().unwrap_or_default();
        let stderr = self.err_reader.join().unwrap_or_default();
        match status {
            Some(status) => Ok(ImageRun {
                status,
                log,
                stderr,
            }),
            None => Err(format!(
                "{} hung: killed after {} s\n{log}{stderr}",
                self.elf.display(),
                self.limit.as_secs()
            )),
        }
    }

    /// Stops QEMU now (a failed exchange); the log is still collected.
    pub(super) fn kill(&mut self) {
        let _ = self.qemu.kill();
        let _ = self.qemu.wait();
    }

    /// Stops QEMU and returns what it logged, for an error message.
    pub(super) fn abort(mut self) -> String {
        self.kill();
        self.wait()
            .map(|r| format!("{}{}", r.log, r.stderr))
            .unwrap_or_else(|e| e)
    }
}

/// A free TCP port on 127.0.0.1 for QEMU's serial server. (Another process
/// could take it between here and QEMU's bind; QEMU then fails to start
/// and the caller retries with a new port.)
pub(super) fn free_port() -> Result<u16> {
    let l = TcpListener::bind("127.0.0.1:0").map_err(|e| format!("bind 127.0.0.1:0: {e}"))?;
    l.local_addr()
        .map(|a| a.port())
        .map_err(|e| format!("local_addr: {e}"))
}

/// Starts `elf` with USART1 on a TCP server socket and connects to it.
pub(super) fn start_with_serial(elf: &Path) -> Result<(RunningImage, TcpStream, u16)> {
    let mut last_err = String::new();
    for _attempt in 0..3 {
        let port = free_port()?;
        let opts = QemuOpts {
            serial: Some(format!("tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on")),
            ..QemuOpts::default()
        };
        let mut image = start_image(elf, &opts)?;
        // QEMU listens as soon as it has parsed its options and, with
        // wait=on, starts the guest only once we are connected: nothing the
        // image sends at boot can be lost.
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            match TcpStream::connect(("127.0.0.1", port)) {
                Ok(stream) => return Ok((image, stream, port)),
                Err(e) => {
                    if let Ok(Some(status)) = image.qemu.try_wait() {
                        last_err = format!("qemu exited ({status}) before listening on {port}");
                        let _ = image.abort();
                        break;
                    }
                    if Instant::now() > deadline {
                        last_err = format!("cannot connect to QEMU's serial on {port}: {e}");
                        let _ = image.abort();
                        break;
                    }
                    thread::sleep(Duration::from_millis(20));
                }
            }
        }
    }
    Err(last_err)
}

pub(super) fn describe(status: &ExitStatus) -> String {
    match status.code() {
        Some(c) => format!("exit status {c}"),
        None => "killed by a signal".into(),
    }
}
