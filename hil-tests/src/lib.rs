//! Support of the HIL tests: boots the link firmware in QEMU with UART0 on a pty and hands
//! out the pty's path; decodes the firmware's defmt log from QEMU's stdout (printed to
//! stderr as it arrives, kept for assertions). The QEMU process is killed when the [`Qemu`]
//! is dropped.
#![warn(missing_docs)]

pub mod jitter;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{mpsc, Arc, Mutex};
use std::time::{Duration, Instant};

use msreg_host::link::defmt::{self, Decoded};

/// Workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from(".."), Path::to_path_buf)
}

/// The link firmware ELF (built by `tools/firmware.sh build`).
pub fn firmware_elf() -> PathBuf {
    root().join("firmware/target/thumbv7em-none-eabihf/release/link")
}

/// Builds the firmware once per process (a no-op when it is up to date).
pub fn build_firmware() -> Result<(), String> {
    static BUILT: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    BUILT
        .get_or_init(|| {
            let status = Command::new(root().join("tools/firmware.sh"))
                .arg("build")
                .stdin(Stdio::null())
                .status()
                .map_err(|e| format!("cannot run tools/firmware.sh build: {e}"))?;
            if !status.success() {
                return Err(format!("tools/firmware.sh build failed: {status}"));
            }
            if !firmware_elf().exists() {
                return Err(format!(
                    "{} missing after the build",
                    firmware_elf().display()
                ));
            }
            Ok(())
        })
        .clone()
}

/// A running QEMU with the link firmware.
pub struct Qemu {
    child: Child,
    /// The guest's UART0, e.g. `/dev/pts/3`.
    pub pty: String,
    log: Arc<Mutex<Vec<Decoded>>>,
}

impl Qemu {
    /// Boots the firmware; fails if QEMU does not print its pty within `timeout`.
    pub fn boot(timeout: Duration) -> Result<Self, String> {
        build_firmware()?;
        let mut child = Command::new("qemu-system-arm")
            .args([
                "-cpu",
                "cortex-m4",
                "-machine",
                "mps2-an386",
                "-display",
                "none",
                "-monitor",
                "none",
                "-semihosting-config",
                "enable=on,target=native",
                "-serial",
                "pty",
                "-kernel",
            ])
            .arg(firmware_elf())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                format!("cannot start qemu-system-arm (tools/setup.sh installs it): {e}")
            })?;
        let Some(stdout) = child.stdout.take() else {
            let _ = child.kill();
            return Err("no stdout from QEMU".into());
        };
        let table = defmt::Table::from_elf(&firmware_elf()).map_err(|e| e.to_string())?;
        let log = Arc::new(Mutex::new(Vec::new()));
        let (tx, rx) = mpsc::channel();
        let sink = Arc::clone(&log);
        std::thread::spawn(move || {
            // Keeps reading so QEMU never blocks on a full pipe: QEMU's own text line with the
            // pty, then the firmware's defmt frames.
            let mut stdout = stdout;
            let mut stream = defmt::Stream::new(table);
            let mut buf = [0u8; 1024];
            while let Ok(n) = stdout.read(&mut buf) {
                if n == 0 {
                    break;
                }
                for item in stream.push(&buf[..n]) {
                    match &item {
                        Decoded::Text(line) => {
                            if let Some(i) = line.find("/dev/pts/") {
                                let path: String = line[i..]
                                    .chars()
                                    .take_while(|c| !c.is_whitespace())
                                    .collect();
                                let _ = tx.send(path);
                            }
                        }
                        Decoded::Log(l) => eprintln!("device log: {l}"),
                        Decoded::Bad(why) => eprintln!("device log: undecodable frame ({why})"),
                    }
                    if let Ok(mut log) = sink.lock() {
                        log.push(item);
                    }
                }
            }
        });
        match rx.recv_timeout(timeout) {
            Ok(pty) => Ok(Self { child, pty, log }),
            Err(_) => {
                let _ = child.kill();
                let _ = child.wait();
                Err(format!(
                    "QEMU printed no 'char device redirected to /dev/pts/N' within {:.0} s",
                    timeout.as_secs_f64()
                ))
            }
        }
    }

    /// Everything decoded from QEMU's stdout so far (QEMU's text and the firmware's log).
    pub fn log(&self) -> Vec<Decoded> {
        self.log.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// The firmware log lines whose format starts with `prefix`, waiting up to `timeout`
    /// until there are at least `count` (semihosting output trails the serial answers).
    pub fn wait_for_log(
        &self,
        prefix: &str,
        count: usize,
        timeout: Duration,
    ) -> Vec<defmt::LogLine> {
        let deadline = Instant::now() + timeout;
        loop {
            let found: Vec<defmt::LogLine> = self
                .log()
                .into_iter()
                .filter_map(|d| match d {
                    Decoded::Log(l) if l.format.starts_with(prefix) => Some(l),
                    _ => None,
                })
                .collect();
            if found.len() >= count || Instant::now() >= deadline {
                return found;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Frames of QEMU's stdout that did not decode (should be none).
    pub fn undecodable_log_frames(&self) -> Vec<defmt::DecodeError> {
        self.log()
            .into_iter()
            .filter_map(|d| match d {
                Decoded::Bad(why) => Some(why),
                _ => None,
            })
            .collect()
    }

    /// True while QEMU runs (the firmware never exits on its own).
    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
