//! YAML helpers: typed reading with file:line:column errors, and float
//! formatting that both serde_yaml and PyYAML (Kalibr's YAML 1.1 reader)
//! read back as the same float.

use std::path::Path;

use serde::de::DeserializeOwned;

use super::csv::{io_error, read_text};
use super::error::DatasetError;

/// Reads and deserializes a YAML file; unknown keys are ignored by the types.
pub(crate) fn read_yaml<T: DeserializeOwned>(path: &Path) -> Result<T, DatasetError> {
    let text = read_text(path)?;
    parse_yaml(path, &text)
}

/// Deserializes YAML `text` that came from `path`.
pub(crate) fn parse_yaml<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T, DatasetError> {
    serde_yaml::from_str(text).map_err(|e| {
        let location = e.location();
        DatasetError::Yaml {
            path: path.to_path_buf(),
            line: location.as_ref().map(serde_yaml::Location::line),
            column: location.as_ref().map(serde_yaml::Location::column),
            message: e.to_string(),
        }
    })
}

/// Writes `text` to `path`.
pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(|source| io_error(path, source))
}

/// A YAML float scalar that round-trips exactly: shortest digits, always a
/// `.` in the mantissa and a signed exponent (YAML 1.1 needs both).
pub(crate) fn yaml_float(x: f64) -> String {
    if x.is_nan() {
        return ".nan".to_string();
    }
    if x.is_infinite() {
        return if x > 0.0 { ".inf" } else { "-.inf" }.to_string();
    }
    let debug = format!("{x:?}");
    match debug.split_once('e') {
        None => debug,
        Some((mantissa, exponent)) => {
            let mantissa = if mantissa.contains('.') {
                mantissa.to_string()
            } else {
                format!("{mantissa}.0")
            };
            let exponent = if exponent.starts_with('-') {
                exponent.to_string()
            } else {
                format!("+{exponent}")
            };
            format!("{mantissa}e{exponent}")
        }
    }
}

/// A flow sequence `[a, b, c]` of YAML floats.
pub(crate) fn yaml_float_list(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|&v| yaml_float(v)).collect();
    format!("[{}]", items.join(", "))
}

/// A YAML string scalar (JSON strings are valid double-quoted YAML scalars).
pub(crate) fn yaml_string(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_else(|_| format!("{s:?}"))
}

/// Checks that a noise or rate parameter is finite and not negative.
pub(crate) fn check_non_negative(path: &Path, key: &str, value: f64) -> Result<(), DatasetError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(DatasetError::InvalidValue {
            path: path.to_path_buf(),
            message: format!("`{key}` must be a finite number >= 0, found {value}"),
        })
    }
}

/// Checks that a rate is finite and positive.
pub(crate) fn check_positive(path: &Path, key: &str, value: f64) -> Result<(), DatasetError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(DatasetError::InvalidValue {
            path: path.to_path_buf(),
            message: format!("`{key}` must be a finite number > 0, found {value}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn yaml_floats_round_trip_through_serde_yaml() {
        for x in [
            0.0, 1.0, -9.81, 6.1e-5, 1e-7, 4.0e-6, 1.5e20, 1e300, 123.456,
        ] {
            let text = yaml_float(x);
            let back: f64 = serde_yaml::from_str(&text).unwrap_or(f64::NAN);
            assert_eq!(back.to_bits(), x.to_bits(), "{x} -> {text}");
        }
    }

    #[test]
    fn yaml_floats_have_dot_and_signed_exponent() {
        assert_eq!(yaml_float(1e-7), "1.0e-7");
        assert_eq!(yaml_float(1e20), "1.0e+20");
        assert_eq!(yaml_float(2.0), "2.0");
    }
}
