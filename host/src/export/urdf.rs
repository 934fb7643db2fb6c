//! URDF: link `imu0` and one fixed joint + link per sensor; the joint's `origin` is the
//! sensor frame in `imu0` (p_imu0 = T * p_sensor), `rpy` fixed-axis: R = Rz(y) Ry(p) Rx(r).

use super::text::float;
use super::{t_imu0_sensor, ExportError, ExportFile};
use crate::dataset::CalibrationResult;

pub(super) fn render(result: &CalibrationResult) -> Result<Vec<ExportFile>, ExportError> {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<!-- msreg calibration: joint origins are p_imu0 = T * p_sensor; rpy is R = Rz(yaw) Ry(pitch) Rx(roll) -->\n<robot name=\"msreg_rig\">\n  <link name=\"imu0\"/>\n",
    );
    for (name, section) in result.sections() {
        let Some(t) = t_imu0_sensor(name, result) else {
            if section.extrinsic.is_some() {
                s += &format!(
                    "  <!-- {name}: a sensor pair, not a frame; see the result file -->\n"
                );
            }
            continue;
        };
        let e = section.extrinsic.as_ref().expect("has transform");
        let (r, p, y) = t.rotation.euler_angles();
        let v = t.translation.vector;
        s += &format!(
            "  <!-- {name}: timeshift {} s; sigma_rot_deg {} {} {}; sigma_trans_m {} {} {} -->\n",
            float(e.timeshift_s),
            float(e.sigma_rot_deg.x),
            float(e.sigma_rot_deg.y),
            float(e.sigma_rot_deg.z),
            float(e.sigma_trans_m.x),
            float(e.sigma_trans_m.y),
            float(e.sigma_trans_m.z)
        );
        s += &format!(
            "  <link name=\"{name}\"/>\n  <joint name=\"imu0_to_{name}\" type=\"fixed\">\n    <parent link=\"imu0\"/>\n    <child link=\"{name}\"/>\n    <origin xyz=\"{} {} {}\" rpy=\"{} {} {}\"/>\n  </joint>\n",
            float(v.x), float(v.y), float(v.z), float(r), float(p), float(y)
        );
    }
    s += "</robot>\n";
    Ok(vec![ExportFile {
        name: "msreg_rig.urdf".into(),
        text: s,
    }])
}
