//! Decoder of the link firmware's `defmt` log (QEMU's stdout under semihosting), so its log
//! lines are readable on the host without a separate tool (`msreg link log`).
//!
//! defmt sends an index per log statement instead of its text; the texts are symbols of the
//! ELF's `.defmt` section (JSON names with the level tag and the format string, the index
//! is the symbol's value). Frames are rzCOBS-encoded and end at `0x00`. Arguments follow the
//! index in little-endian fixed width; `str` is a u32 length and the bytes.
//!
//! Supported: what the firmware uses, format parameters with an explicit primitive type
//! (`{=u32}`, `{=f32}`, `{=str}`, ...) and no timestamp. Anything else (`{}` with a `Format`
//! impl, `{=istr}`, slices) is reported as an undecodable frame, never misread. The rules
//! are pinned by tests on bytes captured from the firmware.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

use super::LinkError;

/// Severity of a log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// `defmt::trace!`.
    Trace,
    /// `defmt::debug!`.
    Debug,
    /// `defmt::info!`.
    Info,
    /// `defmt::warn!`.
    Warn,
    /// `defmt::error!`.
    Error,
    /// `defmt::println!` and other untagged output.
    Print,
}

impl Level {
    fn from_tag(tag: &str) -> Option<Self> {
        Some(match tag {
            "defmt_trace" => Level::Trace,
            "defmt_debug" => Level::Debug,
            "defmt_info" => Level::Info,
            "defmt_warn" => Level::Warn,
            "defmt_error" => Level::Error,
            "defmt_println" => Level::Print,
            _ => return None,
        })
    }

    /// Fixed-width label.
    pub fn label(self) -> &'static str {
        match self {
            Level::Trace => "TRACE",
            Level::Debug => "DEBUG",
            Level::Info => "INFO ",
            Level::Warn => "WARN ",
            Level::Error => "ERROR",
            Level::Print => "     ",
        }
    }
}

/// One decoded argument.
#[derive(Debug, Clone, PartialEq)]
pub enum Arg {
    /// Any unsigned integer (and `bool` as 0/1).
    Unsigned(u64),
    /// Any signed integer.
    Signed(i64),
    /// `f32` or `f64`.
    Float(f64),
    /// `str`.
    Str(String),
    /// `char`.
    Char(char),
    /// `bool`.
    Bool(bool),
}

impl Arg {
    /// The value as an unsigned integer, if it is one.
    pub fn as_u64(&self) -> Option<u64> {
        match *self {
            Arg::Unsigned(v) => Some(v),
            _ => None,
        }
    }

    /// The value as a float, if it is one.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Arg::Float(v) => Some(v),
            _ => None,
        }
    }
}

/// One log line from the device.
#[derive(Debug, Clone, PartialEq)]
pub struct LogLine {
    /// Severity.
    pub level: Level,
    /// The format string as written in the firmware (to find a line by its kind).
    pub format: String,
    /// The arguments in order.
    pub args: Vec<Arg>,
    /// The formatted text.
    pub text: String,
}

impl std::fmt::Display for LogLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} {}", self.level.label(), self.text)
    }
}

/// What one frame of the stream was.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// A log line.
    Log(LogLine),
    /// Not defmt but readable text (QEMU's own messages before the firmware starts).
    Text(String),
    /// A frame that did not decode, and why.
    Bad(DecodeError),
}

/// Why a frame did not decode.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// Not valid rzCOBS.
    #[error("{0}")]
    Rzcobs(&'static str),
    /// The frame is shorter than a log index.
    #[error("frame shorter than an index")]
    NoIndex,
    /// The ELF has no statement with this index.
    #[error("unknown log index {index}")]
    UnknownIndex {
        /// The index read.
        index: u16,
    },
    /// The statement's format string cannot be decoded.
    #[error(transparent)]
    Format(#[from] FormatError),
    /// The frame ends before the statement's arguments do.
    #[error("log index {index} ({format:?}): arguments cut short")]
    CutShort {
        /// The statement's index.
        index: u16,
        /// Its format string.
        format: String,
    },
    /// The frame exceeds the decoder's buffer.
    #[error("frame over {max} bytes")]
    Oversize {
        /// The buffer size, bytes.
        max: usize,
    },
}

/// Why a defmt format string cannot be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FormatError {
    /// A `{` without its `}`.
    #[error("unterminated parameter in {format:?}")]
    Unterminated {
        /// The format string.
        format: String,
    },
    /// A parameter of a type this decoder does not read.
    #[error("unsupported parameter {{{spec}}} in {format:?}")]
    Unsupported {
        /// The parameter's text between the braces.
        spec: String,
        /// The format string.
        format: String,
    },
}

/// Primitive argument types the decoder reads.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Ty {
    U8,
    U16,
    U32,
    U64,
    I8,
    I16,
    I32,
    I64,
    F32,
    F64,
    Bool,
    Char,
    Str,
}

impl Ty {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "u8" => Ty::U8,
            "u16" => Ty::U16,
            "u32" | "usize" => Ty::U32,
            "u64" => Ty::U64,
            "i8" => Ty::I8,
            "i16" => Ty::I16,
            "i32" | "isize" => Ty::I32,
            "i64" => Ty::I64,
            "f32" => Ty::F32,
            "f64" => Ty::F64,
            "bool" => Ty::Bool,
            "char" => Ty::Char,
            "str" => Ty::Str,
            _ => return None,
        })
    }
}

/// A format string split into literal text and typed parameters.
#[derive(Debug, Clone, PartialEq)]
enum Piece {
    Literal(String),
    Param(Ty),
}

fn parse_format(format: &str) -> Result<Vec<Piece>, FormatError> {
    let mut pieces = Vec::new();
    let mut literal = String::new();
    let mut chars = format.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '{' if chars.peek() == Some(&'{') => {
                chars.next();
                literal.push('{');
            }
            '}' if chars.peek() == Some(&'}') => {
                chars.next();
                literal.push('}');
            }
            '{' => {
                let mut spec = String::new();
                loop {
                    match chars.next() {
                        Some('}') => break,
                        Some(c) => spec.push(c),
                        None => {
                            return Err(FormatError::Unterminated {
                                format: format.to_string(),
                            })
                        }
                    }
                }
                // `{=type}` or `{=type:hint}`; the hint only changes the display.
                let ty = spec
                    .strip_prefix('=')
                    .map(|s| s.split(':').next().unwrap_or(s))
                    .and_then(Ty::parse)
                    .ok_or_else(|| FormatError::Unsupported {
                        spec: spec.clone(),
                        format: format.to_string(),
                    })?;
                if !literal.is_empty() {
                    pieces.push(Piece::Literal(std::mem::take(&mut literal)));
                }
                pieces.push(Piece::Param(ty));
            }
            c => literal.push(c),
        }
    }
    if !literal.is_empty() {
        pieces.push(Piece::Literal(literal));
    }
    Ok(pieces)
}

/// One log statement of the firmware.
#[derive(Debug, Clone)]
struct Statement {
    level: Level,
    format: String,
    /// The parsed format, or why it cannot be decoded.
    pieces: Result<Vec<Piece>, FormatError>,
}

/// The log statements of one firmware ELF, by index.
#[derive(Debug, Clone, Default)]
pub struct Table {
    statements: HashMap<u16, Statement>,
}

impl Table {
    /// Reads the `.defmt` symbols of an ELF built with defmt's rzCOBS encoding.
    pub fn from_elf(path: &Path) -> Result<Self, LinkError> {
        let err = |message: String| LinkError::Record {
            path: path.display().to_string(),
            message,
        };
        let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
        let symbols = elf::defmt_symbols(&bytes).map_err(|m| err(m.to_string()))?;
        let mut table = Table::default();
        let mut encoding = None;
        for (name, value) in symbols {
            if let Some(e) = name.strip_prefix("_defmt_encoding_ = ") {
                encoding = Some(e.to_string());
                continue;
            }
            let Ok(index) = u16::try_from(value) else {
                continue;
            };
            if let Some(statement) = Statement::from_symbol(&name) {
                table.statements.insert(index, statement);
            }
        }
        match encoding.as_deref() {
            Some("rzcobs") => Ok(table),
            Some(other) => Err(err(format!(
                "defmt encoding {other:?}; this decoder reads rzcobs (defmt's default)"
            ))),
            None => Err(err("no defmt symbols (not a defmt firmware?)".into())),
        }
    }

    /// Number of log statements known.
    pub fn len(&self) -> usize {
        self.statements.len()
    }

    /// True when the ELF has no log statements.
    pub fn is_empty(&self) -> bool {
        self.statements.is_empty()
    }

    /// Decodes one frame (between two `0x00`, delimiters excluded).
    pub fn decode_frame(&self, encoded: &[u8]) -> Decoded {
        let bad = Decoded::Bad;
        let raw = match rzcobs_decode(encoded) {
            Ok(raw) => raw,
            Err(why) => return text_or(encoded, bad(DecodeError::Rzcobs(why))),
        };
        let Some(index) = raw.get(..2).map(|b| u16::from_le_bytes([b[0], b[1]])) else {
            return text_or(encoded, bad(DecodeError::NoIndex));
        };
        let Some(statement) = self.statements.get(&index) else {
            return text_or(encoded, bad(DecodeError::UnknownIndex { index }));
        };
        let pieces = match &statement.pieces {
            Ok(p) => p,
            Err(why) => return bad(why.clone().into()),
        };
        let mut reader = Reader {
            bytes: &raw[2..],
            at: 0,
        };
        let mut args = Vec::new();
        let mut text = String::new();
        for piece in pieces {
            match piece {
                Piece::Literal(s) => text.push_str(s),
                Piece::Param(ty) => match reader.arg(*ty) {
                    Some(arg) => {
                        write_arg(&mut text, &arg, *ty);
                        args.push(arg);
                    }
                    None => {
                        return bad(DecodeError::CutShort {
                            index,
                            format: statement.format.clone(),
                        })
                    }
                },
            }
        }
        Decoded::Log(LogLine {
            level: statement.level,
            format: statement.format.clone(),
            args,
            text,
        })
    }
}

impl Statement {
    /// From a `.defmt` symbol name: `{"package":..,"tag":"defmt_info","data":"format",..}`.
    fn from_symbol(name: &str) -> Option<Self> {
        let json: serde_json::Value = serde_json::from_str(name).ok()?;
        let level = Level::from_tag(json.get("tag")?.as_str()?)?;
        let format = json.get("data")?.as_str()?.to_string();
        let pieces = parse_format(&format);
        Some(Self {
            level,
            format,
            pieces,
        })
    }
}

/// A non-defmt frame that is plain text (QEMU's "char device redirected ..." line) is shown
/// as text rather than as an error.
fn text_or(encoded: &[u8], otherwise: Decoded) -> Decoded {
    as_text(encoded).map_or(otherwise, Decoded::Text)
}

/// The frame as a text line, when it is one.
fn as_text(encoded: &[u8]) -> Option<String> {
    match std::str::from_utf8(encoded) {
        Ok(s) if s.ends_with('\n') && !s.chars().any(|c| c.is_control() && c != '\n') => {
            Some(s.trim_end().to_string())
        }
        _ => None,
    }
}

fn write_arg(out: &mut String, arg: &Arg, ty: Ty) {
    let _ = match arg {
        Arg::Unsigned(v) => write!(out, "{v}"),
        Arg::Signed(v) => write!(out, "{v}"),
        // An f32 shows its own shortest form, not the f64 widening's digits.
        Arg::Float(v) if ty == Ty::F32 => write!(out, "{}", *v as f32),
        Arg::Float(v) => write!(out, "{v}"),
        Arg::Str(s) => write!(out, "{s}"),
        Arg::Char(c) => write!(out, "{c}"),
        Arg::Bool(b) => write!(out, "{b}"),
    };
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let b = self.bytes.get(self.at..self.at + N)?;
        self.at += N;
        b.try_into().ok()
    }

    fn arg(&mut self, ty: Ty) -> Option<Arg> {
        Some(match ty {
            Ty::U8 => Arg::Unsigned(u64::from(self.take::<1>()?[0])),
            Ty::U16 => Arg::Unsigned(u64::from(u16::from_le_bytes(self.take()?))),
            Ty::U32 => Arg::Unsigned(u64::from(u32::from_le_bytes(self.take()?))),
            Ty::U64 => Arg::Unsigned(u64::from_le_bytes(self.take()?)),
            Ty::I8 => Arg::Signed(i64::from(i8::from_le_bytes(self.take()?))),
            Ty::I16 => Arg::Signed(i64::from(i16::from_le_bytes(self.take()?))),
            Ty::I32 => Arg::Signed(i64::from(i32::from_le_bytes(self.take()?))),
            Ty::I64 => Arg::Signed(i64::from_le_bytes(self.take()?)),
            Ty::F32 => Arg::Float(f64::from(f32::from_le_bytes(self.take()?))),
            Ty::F64 => Arg::Float(f64::from_le_bytes(self.take()?)),
            Ty::Bool => Arg::Bool(self.take::<1>()?[0] != 0),
            Ty::Char => Arg::Char(char::from_u32(u32::from_le_bytes(self.take()?))?),
            Ty::Str => {
                let len = u32::from_le_bytes(self.take()?) as usize;
                let s = self.bytes.get(self.at..self.at.checked_add(len)?)?;
                self.at += len;
                Arg::Str(String::from_utf8_lossy(s).into_owned())
            }
        })
    }
}

/// Decodes one rzCOBS frame (delimiter excluded). The encoder emits the data in groups,
/// each closed by a header byte; the decoder walks the headers from the end:
/// - `0bbbbbbb`: seven bytes, LSB first, bit set = a zero byte, clear = the next data byte;
/// - `1nnnnnnn` (below `0xFF`): `n + 7` data bytes, then a zero byte;
/// - `0xFF`: 134 data bytes.
///
/// The last group may end in zero bytes the frame did not have (defmt pads it); the frame's
/// parser ignores what follows its arguments.
pub fn rzcobs_decode(encoded: &[u8]) -> Result<Vec<u8>, &'static str> {
    // Groups in reverse order; reversed at the end.
    let mut groups: Vec<Vec<u8>> = Vec::new();
    let mut end = encoded.len();
    while end > 0 {
        let header = encoded[end - 1];
        end -= 1;
        let (data_len, group) = if header & 0x80 == 0 {
            let data_len = 7 - header.count_ones() as usize;
            let data = encoded
                .get(
                    end.checked_sub(data_len)
                        .ok_or("rzcobs: group runs past the start")?..end,
                )
                .ok_or("rzcobs: group runs past the start")?;
            let mut data = data.iter();
            let mut group = Vec::with_capacity(7);
            for bit in 0..7 {
                if header & (1 << bit) != 0 {
                    group.push(0);
                } else {
                    group.push(*data.next().ok_or("rzcobs: short group")?);
                }
            }
            (data_len, group)
        } else {
            let (data_len, zero) = if header == 0xFF {
                (134, false)
            } else {
                (usize::from(header & 0x7F) + 7, true)
            };
            let start = end
                .checked_sub(data_len)
                .ok_or("rzcobs: run past the start")?;
            let mut group = encoded[start..end].to_vec();
            if zero {
                group.push(0);
            }
            (data_len, group)
        };
        end -= data_len;
        groups.push(group);
    }
    Ok(groups.into_iter().rev().flatten().collect())
}

/// Splits a byte stream into frames at `0x00` and decodes them; keeps at most `max_frame`
/// bytes of an unfinished frame (longer ones are reported as bad).
pub struct Stream {
    table: Table,
    pending: Vec<u8>,
    overflowed: bool,
}

/// Longest frame the stream buffers (a log line is well under 1 KiB).
const MAX_FRAME: usize = 4096;

impl Stream {
    /// A stream decoder for the firmware described by `table`.
    pub fn new(table: Table) -> Self {
        Self {
            table,
            pending: Vec::new(),
            overflowed: false,
        }
    }

    /// Feeds bytes; returns what completed.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Decoded> {
        let mut out = Vec::new();
        for &b in bytes {
            if b != 0 {
                if self.pending.len() < MAX_FRAME {
                    self.pending.push(b);
                } else {
                    self.overflowed = true;
                }
                continue;
            }
            if self.overflowed {
                out.push(Decoded::Bad(DecodeError::Oversize { max: MAX_FRAME }));
            } else if !self.pending.is_empty() {
                out.push(self.table.decode_frame(&self.pending));
            }
            self.pending.clear();
            self.overflowed = false;
        }
        // QEMU's text lines end in a newline, not in 0x00: show them as they come.
        if self.pending.ends_with(b"\n") {
            if let Some(t) = as_text(&self.pending) {
                out.push(Decoded::Text(t));
                self.pending.clear();
            }
        }
        out
    }
}

/// Just enough of ELF32 (little endian) to list the symbols of the `.defmt` section.
mod elf {
    fn u16_at(b: &[u8], at: usize) -> Option<u32> {
        Some(u32::from(u16::from_le_bytes(
            b.get(at..at + 2)?.try_into().ok()?,
        )))
    }

    fn u32_at(b: &[u8], at: usize) -> Option<u32> {
        Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
    }

    fn c_str(b: &[u8], at: usize) -> Option<&str> {
        let rest = b.get(at..)?;
        let len = rest.iter().position(|&c| c == 0)?;
        std::str::from_utf8(&rest[..len]).ok()
    }

    struct Section {
        name: u32,
        kind: u32,
        offset: usize,
        size: usize,
        link: u32,
    }

    fn sections(b: &[u8]) -> Option<Vec<Section>> {
        let shoff = u32_at(b, 0x20)? as usize;
        let shentsize = u16_at(b, 0x2E)? as usize;
        let shnum = u16_at(b, 0x30)? as usize;
        (0..shnum)
            .map(|i| {
                let at = shoff.checked_add(i.checked_mul(shentsize)?)?;
                Some(Section {
                    name: u32_at(b, at)?,
                    kind: u32_at(b, at + 4)?,
                    offset: u32_at(b, at + 16)? as usize,
                    size: u32_at(b, at + 20)? as usize,
                    link: u32_at(b, at + 24)?,
                })
            })
            .collect()
    }

    /// `(name, value)` of every symbol defined in `.defmt`.
    pub fn defmt_symbols(b: &[u8]) -> Result<Vec<(String, u32)>, &'static str> {
        if b.get(..4) != Some(b"\x7fELF".as_slice()) {
            return Err("not an ELF file");
        }
        if b.get(4) != Some(&1) || b.get(5) != Some(&1) {
            return Err("not a 32-bit little-endian ELF (the Cortex-M firmware)");
        }
        let malformed = "malformed ELF section table";
        let sections = sections(b).ok_or(malformed)?;
        let shstrndx = u16_at(b, 0x32).ok_or(malformed)? as usize;
        let names = sections.get(shstrndx).ok_or(malformed)?;
        let name_of = |s: &Section| c_str(b, names.offset + s.name as usize);
        let defmt = sections
            .iter()
            .position(|s| name_of(s) == Some(".defmt"))
            .ok_or("no .defmt section (not a defmt firmware?)")?;
        let symtab = sections
            .iter()
            .find(|s| s.kind == 2)
            .ok_or("no symbol table (stripped ELF?)")?;
        let strtab = sections.get(symtab.link as usize).ok_or(malformed)?;
        let mut out = Vec::new();
        for at in (symtab.offset..symtab.offset + symtab.size).step_by(16) {
            let (Some(name), Some(value), Some(shndx)) =
                (u32_at(b, at), u32_at(b, at + 4), u16_at(b, at + 14))
            else {
                return Err(malformed);
            };
            if shndx as usize != defmt {
                continue;
            }
            if let Some(name) = c_str(b, strtab.offset + name as usize) {
                out.push((name.to_string(), value));
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> Table {
        let mut t = Table::default();
        for (i, level, format) in [
            (
                1u16,
                Level::Info,
                "msreg link firmware ready: protocol v{=u16}, rx ring {=u32} B, frames up to {=u32} B",
            ),
            (
                2,
                Level::Info,
                "ram: static {=u32} B + stack peak {=u32} B = {=u32} B (target {=u32} B)",
            ),
            (5, Level::Warn, "fault {=str} (#{=u32}), frame {=u32}, stamp {=u64} ns"),
            (9, Level::Info, "bad {} here"),
        ] {
            t.statements.insert(
                i,
                Statement {
                    level,
                    format: format.into(),
                    pieces: parse_format(format),
                },
            );
        }
        t
    }

    /// The first bytes the link firmware wrote to QEMU's stdout (captured), after QEMU's
    /// own line: the boot line and the RAM line.
    const CAPTURED: &[u8] = b"char device redirected to /dev/pts/0 (label serial0)\n\
        \x00\x01\x01\x10\x5a\xe6\x01\x79\x00\
        \x02\x1c\x34\x80\x32\x9b\x9c\xcf\x66\x01\x7b\x00";

    #[test]
    fn captured_firmware_output_decodes() {
        let mut s = Stream::new(table());
        let mut out = Vec::new();
        // Byte by byte, as a pipe may deliver it.
        for b in CAPTURED {
            out.extend(s.push(std::slice::from_ref(b)));
        }
        let texts: Vec<String> = out
            .iter()
            .map(|d| match d {
                Decoded::Log(l) => l.to_string(),
                Decoded::Text(t) => format!("text {t}"),
                Decoded::Bad(b) => format!("bad {b}"),
            })
            .collect();
        assert_eq!(
            texts,
            [
                "text char device redirected to /dev/pts/0 (label serial0)",
                "INFO  msreg link firmware ready: protocol v1, rx ring 4096 B, frames up to 486 B",
                "INFO  ram: static 13340 B + stack peak 39808 B = 53148 B (target 65536 B)",
            ]
        );
        let Decoded::Log(ram) = &out[2] else {
            unreachable!("checked above")
        };
        assert_eq!(ram.args[2].as_u64(), Some(53_148));
    }

    #[test]
    fn rzcobs_groups() {
        // One data byte then six zeros (the encoder's padding of a short last group).
        assert_eq!(rzcobs_decode(&[0x01, 0x7e]), Ok(vec![1, 0, 0, 0, 0, 0, 0]));
        // A run of eight non-zero bytes then a zero: 1nnnnnnn with n = 1.
        let run: Vec<u8> = (1..=8).collect();
        let mut enc = run.clone();
        enc.push(0x81);
        let mut want = run;
        want.push(0);
        assert_eq!(rzcobs_decode(&enc), Ok(want));
        // 134 non-zero bytes: 0xFF.
        let long: Vec<u8> = (0..134).map(|i| (i % 250 + 1) as u8).collect();
        let mut enc = long.clone();
        enc.push(0xFF);
        assert_eq!(rzcobs_decode(&enc), Ok(long));
        // Headers that claim more data than there is are errors, not panics.
        assert!(rzcobs_decode(&[0x00]).is_err());
        assert!(rzcobs_decode(&[0x05, 0x85]).is_err());
        assert!(rzcobs_decode(&[0xFF]).is_err());
    }

    #[test]
    fn strings_and_u64_arguments() {
        // index 5, "crc", count 2, frame 7, stamp 2^40, as raw bytes, then rzcobs-encoded
        // with the simplest valid groups (7 bytes each, header 0 = no zeros elided).
        let mut raw = vec![5, 0];
        raw.extend(3u32.to_le_bytes());
        raw.extend(b"crc");
        raw.extend(2u32.to_le_bytes());
        raw.extend(7u32.to_le_bytes());
        raw.extend((1u64 << 40).to_le_bytes());
        let mut enc = Vec::new();
        for chunk in raw.chunks(7) {
            let mut header = 0u8;
            for (i, &b) in chunk.iter().enumerate() {
                if b == 0 {
                    header |= 1 << i;
                } else {
                    enc.push(b);
                }
            }
            header |= 0x7F & !((1u8 << chunk.len()) - 1);
            enc.push(header);
        }
        let Decoded::Log(line) = table().decode_frame(&enc) else {
            panic!("not decoded: {:?}", table().decode_frame(&enc));
        };
        assert_eq!(line.level, Level::Warn);
        assert_eq!(line.text, "fault crc (#2), frame 7, stamp 1099511627776 ns");
    }

    #[test]
    fn unknown_and_unsupported_statements_are_reported_not_misread() {
        assert!(matches!(
            table().decode_frame(&[0x09, 0x7e]),
            Decoded::Bad(_)
        ));
        assert!(matches!(
            table().decode_frame(&[0x30, 0x7e]),
            Decoded::Bad(_)
        ));
        // Arguments cut short.
        assert!(matches!(
            table().decode_frame(&[0x02, 0x1c, 0x34, 0x7c]),
            Decoded::Bad(_)
        ));
        assert_eq!(
            parse_format("a {{b}} {=f32:.3}"),
            Ok(vec![Piece::Literal("a {b} ".into()), Piece::Param(Ty::F32)])
        );
        let mut text = String::new();
        write_arg(&mut text, &Arg::Float(f64::from(0.1f32)), Ty::F32);
        assert_eq!(text, "0.1");
    }

    #[test]
    fn garbage_never_panics() {
        let mut s = Stream::new(table());
        let mut x = 0x1234_5678u32;
        let bytes: Vec<u8> = (0..20_000)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                (x >> 24) as u8
            })
            .collect();
        let _ = s.push(&bytes);
        assert!(elf::defmt_symbols(&bytes).is_err());
        let mut elf_like = b"\x7fELF\x01\x01".to_vec();
        elf_like.extend(&bytes[..200]);
        assert!(elf::defmt_symbols(&elf_like).is_err());
    }
}
