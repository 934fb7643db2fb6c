//! Support of the HIL tests: boots the link firmware in QEMU with UART0 on a pty and hands
//! out the pty's path. The QEMU process is killed when the [`Qemu`] is dropped.
#![warn(missing_docs)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

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
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            // Keeps reading so QEMU never blocks on a full pipe.
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if let Some(i) = line.find("/dev/pts/") {
                    let path: String = line[i..]
                        .chars()
                        .take_while(|c| !c.is_whitespace())
                        .collect();
                    let _ = tx.send(path);
                }
            }
        });
        match rx.recv_timeout(timeout) {
            Ok(pty) => Ok(Self { child, pty }),
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
