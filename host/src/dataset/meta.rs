//! `dataset.yaml`: which sensors a dataset holds, their rates and a free-text
//! description. Informative: the tools look for the files themselves.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::DatasetError;
use super::yaml::{write_text, yaml_float, yaml_string};

/// Contents of `dataset.yaml`. Every key is optional; unknown keys are ignored.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DatasetYaml {
    /// Sensor directories present, e.g. `["imu0", "pose0"]`.
    #[serde(default)]
    pub sensors: Vec<String>,
    /// Free text (origin, scenario, seed ...).
    #[serde(default)]
    pub description: String,
    /// Nominal rate of each sensor (Hz), keyed by sensor directory.
    #[serde(default, alias = "rates")]
    pub rates_hz: BTreeMap<String, f64>,
}

impl DatasetYaml {
    /// Reads `dataset.yaml`; an empty file is an empty description.
    pub fn read(path: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let path = path.as_ref();
        let text = super::csv::read_text(path)?;
        if text.trim().is_empty() {
            return Ok(Self::default());
        }
        super::yaml::parse_yaml(path, &text)
    }

    /// Writes `dataset.yaml`.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), DatasetError> {
        write_text(path.as_ref(), &self.to_yaml_string())
    }

    /// The YAML text [`DatasetYaml::write`] writes.
    pub fn to_yaml_string(&self) -> String {
        let sensors: Vec<String> = self.sensors.iter().map(|s| yaml_string(s)).collect();
        let mut text = format!(
            "sensors: [{}]\ndescription: {}\nrates_hz:",
            sensors.join(", "),
            yaml_string(&self.description)
        );
        if self.rates_hz.is_empty() {
            text.push_str(" {}\n");
        } else {
            text.push('\n');
            for (sensor, rate) in &self.rates_hz {
                text.push_str(&format!(
                    "  {}: {}\n",
                    yaml_string(sensor),
                    yaml_float(*rate)
                ));
            }
        }
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    #[test]
    fn dataset_yaml_round_trips_and_tolerates_unknown_keys() -> TestResult {
        let dir = tempfile::tempdir()?;
        let path = dir.path().join("dataset.yaml");
        let mut meta = DatasetYaml {
            sensors: vec!["imu0".into(), "pose0".into()],
            description: "sim: seed 7, \"quoted\"\nsecond line".into(),
            ..DatasetYaml::default()
        };
        meta.rates_hz.insert("imu0".into(), 400.0);
        meta.rates_hz.insert("pose0".into(), 12.5);
        meta.write(&path)?;
        assert_eq!(DatasetYaml::read(&path)?, meta);

        std::fs::write(&path, "sensors: [imu0]\nrates: {imu0: 200}\nfuture: 1\n")?;
        let read = DatasetYaml::read(&path)?;
        assert_eq!(read.sensors, vec!["imu0".to_string()]);
        assert_eq!(
            read.rates_hz.get("imu0").map(|r| r.to_bits()),
            Some(200f64.to_bits())
        );

        std::fs::write(&path, "sensors: imu0: x\n")?;
        let err = DatasetYaml::read(&path).err().ok_or("expected an error")?;
        assert!(
            matches!(err, DatasetError::Yaml { line: Some(1), .. }),
            "{err}"
        );
        Ok(())
    }
}
