//! The PCD header: parsed line by line and cross-checked, so every later step
//! can trust field sizes, counts and the point count.

use std::path::Path;

use super::PcdError;

/// Scalar type of a PCD field (`TYPE` letter and `SIZE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PcdScalarType {
    /// `F 4`.
    F32,
    /// `F 8`.
    F64,
    /// `U 1`.
    U8,
    /// `U 2`.
    U16,
    /// `U 4`.
    U32,
    /// `U 8`.
    U64,
    /// `I 1`.
    I8,
    /// `I 2`.
    I16,
    /// `I 4`.
    I32,
    /// `I 8`.
    I64,
}

impl PcdScalarType {
    /// The type for a `TYPE` letter and `SIZE`, if supported.
    pub fn from_type_size(kind: char, size: usize) -> Option<Self> {
        Some(match (kind.to_ascii_uppercase(), size) {
            ('F', 4) => Self::F32,
            ('F', 8) => Self::F64,
            ('U', 1) => Self::U8,
            ('U', 2) => Self::U16,
            ('U', 4) => Self::U32,
            ('U', 8) => Self::U64,
            ('I', 1) => Self::I8,
            ('I', 2) => Self::I16,
            ('I', 4) => Self::I32,
            ('I', 8) => Self::I64,
            _ => return None,
        })
    }

    /// Size in bytes.
    pub fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::F32 | Self::U32 | Self::I32 => 4,
            Self::F64 | Self::U64 | Self::I64 => 8,
        }
    }

    /// Decodes one little-endian value (`bytes.len() >= size()`) as `f64`.
    pub(crate) fn decode_le(self, b: &[u8]) -> f64 {
        fn arr<const N: usize>(b: &[u8]) -> [u8; N] {
            let mut a = [0u8; N];
            a.copy_from_slice(&b[..N]);
            a
        }
        match self {
            Self::F32 => f64::from(f32::from_le_bytes(arr(b))),
            Self::F64 => f64::from_le_bytes(arr(b)),
            Self::U8 => f64::from(b[0]),
            Self::U16 => f64::from(u16::from_le_bytes(arr(b))),
            Self::U32 => f64::from(u32::from_le_bytes(arr(b))),
            Self::U64 => u64::from_le_bytes(arr(b)) as f64,
            Self::I8 => f64::from(i8::from_le_bytes(arr(b))),
            Self::I16 => f64::from(i16::from_le_bytes(arr(b))),
            Self::I32 => f64::from(i32::from_le_bytes(arr(b))),
            Self::I64 => i64::from_le_bytes(arr(b)) as f64,
        }
    }
}

/// One field of the header.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PcdField {
    /// Field name (`x`, `intensity`, `_` for padding, ...).
    pub name: String,
    /// Scalar type.
    pub scalar: PcdScalarType,
    /// Elements per point (`COUNT`).
    pub count: usize,
}

/// Encoding of the data section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PcdDataEncoding {
    /// Whitespace-separated text, one point per line.
    Ascii,
    /// Little-endian records, point after point.
    Binary,
    /// LZF-compressed, field after field (column-major).
    BinaryCompressed,
}

/// A parsed, consistent PCD header.
#[derive(Debug, Clone, PartialEq)]
pub struct PcdHeader {
    /// Fields in record order.
    pub fields: Vec<PcdField>,
    /// `WIDTH`.
    pub width: usize,
    /// `HEIGHT`.
    pub height: usize,
    /// `POINTS` (`WIDTH * HEIGHT` when absent).
    pub points: usize,
    /// The `DATA` encoding.
    pub encoding: PcdDataEncoding,
    /// 1-based line number of the `DATA` line (ascii data starts after it).
    pub data_line: usize,
}

impl PcdHeader {
    /// Bytes of one point record.
    pub fn point_size(&self) -> usize {
        self.fields.iter().map(|f| f.scalar.size() * f.count).sum()
    }

    /// Index of the field called `name`.
    pub fn field_index(&self, name: &str) -> Option<usize> {
        self.fields.iter().position(|f| f.name == name)
    }
}

/// Raw per-keyword values with the line each was found on.
#[derive(Default)]
struct RawHeader<'a> {
    fields: Option<(usize, Vec<&'a str>)>,
    size: Option<(usize, Vec<&'a str>)>,
    kind: Option<(usize, Vec<&'a str>)>,
    count: Option<(usize, Vec<&'a str>)>,
    width: Option<(usize, usize)>,
    height: Option<(usize, usize)>,
    points: Option<(usize, usize)>,
}

/// Parses the header at the start of `bytes`; returns it with the byte offset
/// where the data section starts.
pub(crate) fn parse_header(path: &Path, bytes: &[u8]) -> Result<(PcdHeader, usize), PcdError> {
    let err = |line: usize, message: String| PcdError::Header {
        path: path.to_path_buf(),
        line,
        message,
    };
    let mut raw = RawHeader::default();
    let mut offset = 0usize;
    let mut line_no = 0usize;
    while offset < bytes.len() {
        line_no += 1;
        let end = bytes[offset..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |p| offset + p);
        let line = std::str::from_utf8(&bytes[offset..end])
            .map_err(|_| err(line_no, "header line is not text".into()))?
            .trim();
        offset = (end + 1).min(bytes.len());
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tokens = line.split_whitespace();
        let keyword = tokens.next().unwrap_or_default().to_ascii_uppercase();
        let values: Vec<&str> = tokens.collect();
        let number = |values: &[&str]| -> Result<usize, PcdError> {
            match values {
                [v] => v.parse::<usize>().map_err(|_| {
                    err(
                        line_no,
                        format!("{keyword} `{v}` is not a non-negative integer"),
                    )
                }),
                _ => Err(err(line_no, format!("{keyword} needs exactly one value"))),
            }
        };
        match keyword.as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => raw.fields = Some((line_no, values)),
            "SIZE" => raw.size = Some((line_no, values)),
            "TYPE" => raw.kind = Some((line_no, values)),
            "COUNT" => raw.count = Some((line_no, values)),
            "WIDTH" => raw.width = Some((line_no, number(&values)?)),
            "HEIGHT" => raw.height = Some((line_no, number(&values)?)),
            "POINTS" => raw.points = Some((line_no, number(&values)?)),
            "DATA" => {
                let encoding = match values.first().map(|v| v.to_ascii_lowercase()).as_deref() {
                    Some("ascii") => PcdDataEncoding::Ascii,
                    Some("binary") => PcdDataEncoding::Binary,
                    Some("binary_compressed") => PcdDataEncoding::BinaryCompressed,
                    other => {
                        return Err(err(
                            line_no,
                            format!(
                                "DATA `{}` is not ascii, binary or binary_compressed",
                                other.unwrap_or("")
                            ),
                        ))
                    }
                };
                let header = assemble(path, raw, encoding, line_no)?;
                return Ok((header, offset));
            }
            other => return Err(err(line_no, format!("unknown keyword `{other}`"))),
        }
    }
    Err(err(
        line_no.max(1),
        "no DATA line: the header never ends".into(),
    ))
}

/// Cross-checks the raw header lines and builds the field list.
fn assemble(
    path: &Path,
    raw: RawHeader<'_>,
    encoding: PcdDataEncoding,
    data_line: usize,
) -> Result<PcdHeader, PcdError> {
    let err = |line: usize, message: String| PcdError::Header {
        path: path.to_path_buf(),
        line,
        message,
    };
    let (fields_line, names) = raw
        .fields
        .ok_or_else(|| err(data_line, "FIELDS line missing before DATA".into()))?;
    if names.is_empty() {
        return Err(err(fields_line, "FIELDS lists no field".into()));
    }
    let n = names.len();
    let (size_line, sizes) = raw
        .size
        .ok_or_else(|| err(data_line, "SIZE line missing before DATA".into()))?;
    let (type_line, kinds) = raw
        .kind
        .ok_or_else(|| err(data_line, "TYPE line missing before DATA".into()))?;
    for (line, what, len) in [
        (size_line, "SIZE", sizes.len()),
        (type_line, "TYPE", kinds.len()),
    ] {
        if len != n {
            return Err(err(
                line,
                format!("{what} has {len} entries, FIELDS has {n}"),
            ));
        }
    }
    let counts: Vec<usize> = match raw.count {
        None => vec![1; n],
        Some((line, counts)) => {
            if counts.len() != n {
                return Err(err(
                    line,
                    format!("COUNT has {} entries, FIELDS has {n}", counts.len()),
                ));
            }
            counts
                .iter()
                .map(|c| match c.parse::<usize>() {
                    Ok(v) if v > 0 => Ok(v),
                    _ => Err(err(line, format!("COUNT `{c}` is not a positive integer"))),
                })
                .collect::<Result<_, _>>()?
        }
    };
    let fields = (0..n)
        .map(|i| {
            parse_field(
                path,
                names[i],
                (size_line, sizes[i]),
                (type_line, kinds[i]),
                counts[i],
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (width_line, width) = raw
        .width
        .ok_or_else(|| err(data_line, "WIDTH line missing before DATA".into()))?;
    let height = raw.height.map_or(1, |(_, h)| h);
    let expected = width
        .checked_mul(height)
        .ok_or_else(|| err(width_line, "WIDTH * HEIGHT overflows".into()))?;
    let points = match raw.points {
        None => expected,
        Some((line, p)) if p != expected => {
            return Err(err(
                line,
                format!("POINTS {p} differs from WIDTH * HEIGHT = {expected}"),
            ))
        }
        Some((_, p)) => p,
    };
    for required in ["x", "y", "z"] {
        if !names.contains(&required) {
            return Err(err(
                fields_line,
                format!("required field `{required}` missing"),
            ));
        }
    }
    Ok(PcdHeader {
        fields,
        width,
        height,
        points,
        encoding,
        data_line,
    })
}

/// One field from its name, `(line, SIZE text)`, `(line, TYPE text)` and count.
fn parse_field(
    path: &Path,
    name: &str,
    (size_line, size_text): (usize, &str),
    (type_line, kind_text): (usize, &str),
    count: usize,
) -> Result<PcdField, PcdError> {
    let err = |line: usize, message: String| PcdError::Header {
        path: path.to_path_buf(),
        line,
        message,
    };
    let size: usize = size_text
        .parse()
        .map_err(|_| err(size_line, format!("SIZE `{size_text}` is not an integer")))?;
    let mut letters = kind_text.chars();
    let kind = match (letters.next(), letters.next()) {
        (Some(k), None) => k,
        _ => {
            return Err(err(
                type_line,
                format!("TYPE `{kind_text}` is not one letter"),
            ))
        }
    };
    let scalar =
        PcdScalarType::from_type_size(kind, size).ok_or_else(|| PcdError::UnsupportedType {
            path: path.to_path_buf(),
            line: type_line,
            field: name.to_string(),
            kind,
            size,
        })?;
    Ok(PcdField {
        name: name.to_string(),
        scalar,
        count,
    })
}
