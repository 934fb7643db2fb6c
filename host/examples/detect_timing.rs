//! The msreg side of the side-by-side checkerboard benchmark `tools/detect_vs_opencv.py`
//! (docs/benchmarks.md): a line protocol on stdin/stdout, so the driver can interleave
//! single detections of msreg and OpenCV on the same images in one run.
//!
//! Usage: `detect_timing [default|opencv]` (detector settings: `DetectorParams::default()`
//! or `DetectorParams::opencv_compatible()`). Commands, one per line:
//! - `load <rows> <cols> <path>` -> `ok <index>` (the image is decoded once, here);
//! - `time <index>` -> `<wall ms> <cpu ms> <outcome>`: one detection, timed in-process
//!   (decoding excluded): wall-clock time and the CPU time of all the process's threads
//!   (time lost to other processes on a shared machine is not counted); outcome `found`
//!   or the `NoDetection` kind;
//! - `corners <index>` -> `x,y x,y ...` in Kalibr id order (empty when not found);
//! - `profile <index> <repeats>` -> `<milliseconds>`: repeated detections (for `perf`).
//!
//! Anything else answers `err <message>`.

use std::io::{BufRead, Write};
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use msreg_host::vision::{detect_checkerboard, DetectorParams, GrayImage};

struct Loaded {
    img: GrayImage,
    rows: usize,
    cols: usize,
}

fn main() -> Result<()> {
    let params = match std::env::args().nth(1).as_deref() {
        None | Some("default") => DetectorParams::default(),
        Some("opencv") => DetectorParams::opencv_compatible(),
        Some(other) => bail!("unknown settings {other:?} (default|opencv)"),
    };
    let mut images: Vec<Loaded> = Vec::new();
    let stdin = std::io::stdin();
    let mut out = std::io::stdout().lock();
    for line in stdin.lock().lines() {
        let line = line?;
        let reply = answer(&line, &mut images, &params).unwrap_or_else(|e| format!("err {e:#}"));
        writeln!(out, "{reply}")?;
        out.flush()?;
    }
    Ok(())
}

fn answer(line: &str, images: &mut Vec<Loaded>, params: &DetectorParams) -> Result<String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let index = |k: usize| -> Result<&Loaded> {
        let i: usize = words.get(k).context("index missing")?.parse()?;
        images.get(i).context("no such image")
    };
    match words.first().copied() {
        Some("load") => {
            let (rows, cols) = (words.get(1), words.get(2));
            let rows: usize = rows.context("rows missing")?.parse()?;
            let cols: usize = cols.context("cols missing")?.parse()?;
            let path = line.splitn(4, ' ').nth(3).context("path missing")?;
            let img = GrayImage::load(Path::new(path))?;
            images.push(Loaded { img, rows, cols });
            Ok(format!("ok {}", images.len() - 1))
        }
        Some("time") => {
            let l = index(1)?;
            let (start, cpu_start) = (Instant::now(), cpu_ns()?);
            let result = detect_checkerboard(&l.img, l.rows, l.cols, params);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            let cpu_ms = cpu_ns()?.saturating_sub(cpu_start) as f64 * 1e-6;
            let outcome = match result {
                Ok(_) => "found".to_string(),
                Err(e) => format!("{e:?}")
                    .split([' ', '{', '('])
                    .next()
                    .unwrap_or("none")
                    .to_string(),
            };
            Ok(format!("{ms:.4} {cpu_ms:.4} {outcome}"))
        }
        Some("corners") => {
            let l = index(1)?;
            let corners = detect_checkerboard(&l.img, l.rows, l.cols, params)
                .map(|d| d.corners)
                .unwrap_or_default();
            let text: Vec<String> = corners
                .iter()
                .map(|p| format!("{:.5},{:.5}", p.x, p.y))
                .collect();
            Ok(text.join(" "))
        }
        Some("profile") => {
            let l = index(1)?;
            let repeats: usize = words.get(2).context("repeats missing")?.parse()?;
            let start = Instant::now();
            for _ in 0..repeats {
                let _ = detect_checkerboard(&l.img, l.rows, l.cols, params);
            }
            Ok(format!(
                "{:.4}",
                start.elapsed().as_secs_f64() * 1e3 / repeats.max(1) as f64
            ))
        }
        _ => bail!("unknown command {line:?}"),
    }
}

/// CPU time of all this process's threads so far, nanoseconds
/// (`CLOCK_PROCESS_CPUTIME_ID`).
fn cpu_ns() -> Result<u64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        bail!("clock_gettime(CLOCK_PROCESS_CPUTIME_ID) failed");
    }
    Ok(ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64)
}
