//! The result file's numbers in the report: the YAML text a command writes is embedded in
//! its JSON report under [`KEY`] (parsed from that same text, so every number is the file's,
//! bit for bit) and drawn as the page's result tables. The filter's history is not a source
//! of the result: a pipeline may replace what the filter ended with (a DoF back at its prior,
//! a yaw from another fit), and the file is what a user copies.

use nalgebra::{Matrix3, Rotation3};
use serde_json::Value;

use super::data::{num, nums, ResultRow, DOF};

/// The report's key holding the result file.
pub const KEY: &str = "result_file";

/// The result file's YAML text as a JSON value (mapping keys as strings: an infrastructure
/// camera's id `7` becomes `"7"`).
pub fn value_of(yaml: &str) -> Result<Value, serde_yaml::Error> {
    serde_yaml::from_str(yaml).map(|v| json_of(&v))
}

fn json_of(v: &serde_yaml::Value) -> Value {
    use serde_yaml::Value as Y;
    match v {
        Y::Null => Value::Null,
        Y::Bool(b) => Value::Bool(*b),
        Y::Number(n) => match (n.as_i64(), n.as_u64(), n.as_f64()) {
            (Some(i), _, _) => Value::from(i),
            (None, Some(u), _) => Value::from(u),
            (None, None, Some(f)) => {
                serde_json::Number::from_f64(f).map_or(Value::Null, Value::Number)
            }
            _ => Value::Null,
        },
        Y::String(s) => Value::String(s.clone()),
        Y::Sequence(items) => Value::Array(items.iter().map(json_of).collect()),
        Y::Mapping(map) => {
            Value::Object(map.iter().map(|(k, v)| (key_text(k), json_of(v))).collect())
        }
        Y::Tagged(t) => json_of(&t.value),
    }
}

fn key_text(k: &serde_yaml::Value) -> String {
    match k {
        serde_yaml::Value::String(s) => s.clone(),
        serde_yaml::Value::Number(n) => n.to_string(),
        serde_yaml::Value::Bool(b) => b.to_string(),
        other => serde_yaml::to_string(other)
            .unwrap_or_default()
            .trim()
            .to_string(),
    }
}

/// One transform of the result file, in display units.
#[derive(Debug, Clone, PartialEq)]
pub struct ResultTable {
    /// Where it is in the file: `pose0.T_imu_pose`, `cam1.T_cn_cnm1`,
    /// `infra.cameras.7.T_world_cam`.
    pub label: String,
    /// Element id of its table: `result-` and the label with `.` as `-`.
    pub id: String,
    /// Rotation vector (deg), translation (mm) and, where the section has one, the time
    /// shift (ms), with the file's 1-sigma (NaN where the file gives none).
    pub rows: Vec<ResultRow>,
    /// The section's `held` list (names as in the file).
    pub held: Vec<String>,
}

impl ResultTable {
    /// Whether the row named `dof` (`rx` ... `t_d`) is held.
    pub fn is_held(&self, dof: &str) -> bool {
        let name = match dof {
            "rx" => "rotation_x",
            "ry" => "rotation_y",
            "rz" => "rotation_z",
            "tx" => "translation_x",
            "ty" => "translation_y",
            "tz" => "translation_z",
            "t_d" => "timeshift",
            _ => return false,
        };
        self.held.iter().any(|h| h == name)
    }
}

/// Every transform (a `T_*` key holding four rows of four numbers) of the result file
/// `file` (the report's [`KEY`]), in file order.
pub fn tables(file: &Value) -> Vec<ResultTable> {
    let mut out = Vec::new();
    walk(file, "", &mut out);
    out
}

fn walk(v: &Value, path: &str, out: &mut Vec<ResultTable>) {
    let join = |key: &str| {
        if path.is_empty() {
            key.to_string()
        } else {
            format!("{path}.{key}")
        }
    };
    match v {
        Value::Object(map) => {
            for (key, value) in map {
                if key.starts_with("T_") {
                    if let Some(t) = table(map, key, &join(key)) {
                        out.push(t);
                        continue;
                    }
                }
                walk(value, &join(key), out);
            }
        }
        Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                walk(item, &join(&i.to_string()), out);
            }
        }
        _ => {}
    }
}

/// The table of transform `key` of section `map`, if it is four rows of four numbers.
fn table(map: &serde_json::Map<String, Value>, key: &str, label: &str) -> Option<ResultTable> {
    let m = map.get(key)?.as_array()?;
    if m.len() != 4 || m.iter().any(|r| r.as_array().map(Vec::len) != Some(4)) {
        return None;
    }
    let rows: [[f64; 4]; 4] = std::array::from_fn(|r| nums(m.get(r)));
    let rotation = Rotation3::from_matrix(&Matrix3::from_fn(|r, c| rows[r][c]));
    let rv = rotation.scaled_axis();
    let suffix = if key == "T_cn_cnm1" { "_cn_cnm1" } else { "" };
    let sr: [f64; 3] = nums(map.get(&format!("sigma_rot_deg{suffix}")));
    let st: [f64; 3] = nums(map.get(&format!("sigma_trans_m{suffix}")));
    let mut out: Vec<ResultRow> = (0..6)
        .map(|i| {
            if i < 3 {
                (DOF[i].0, rv[i].to_degrees(), sr[i], "deg")
            } else {
                (DOF[i].0, rows[i - 3][3] * 1e3, st[i - 3] * 1e3, "mm")
            }
        })
        .collect();
    let timeshift = map
        .iter()
        .find(|(k, v)| k.starts_with("timeshift") && v.is_number());
    if let (Some((_, t)), "") = (timeshift, suffix) {
        out.push((DOF[6].0, num(Some(t)) * 1e3, f64::NAN, "ms"));
    }
    let held = map
        .get("held")
        .and_then(Value::as_array)
        .map(|a| {
            a.iter()
                .filter_map(Value::as_str)
                .map(str::to_string)
                .collect()
        })
        .unwrap_or_default();
    Some(ResultTable {
        label: label.to_string(),
        id: format!("result-{}", label.replace('.', "-")),
        rows: out,
        held,
    })
}
