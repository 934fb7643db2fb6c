//! ROS 2 static transforms, parent `imu0`, child the sensor: translation and quaternion
//! of T_imu0_sensor (p_imu0 = T * p_sensor), as `static_transform_publisher` command
//! lines and as a YAML list.

use super::text::{float, quaternion_xyzw};
use super::{t_imu0_sensor, ExportError, ExportFile};
use crate::dataset::CalibrationResult;

pub(super) fn render(result: &CalibrationResult) -> Result<Vec<ExportFile>, ExportError> {
    let mut sh = String::from("#!/bin/sh\n# msreg static transforms: p_imu0 = T * p_child\n");
    let mut yaml = String::from("# msreg static transforms: p_parent = T * p_child\n");
    for (name, _) in result.sections() {
        let Some(t) = t_imu0_sensor(name, result) else {
            continue;
        };
        let v = t.translation.vector.map(float);
        let q = quaternion_xyzw(&t).map(float);
        sh += &format!(
            "ros2 run tf2_ros static_transform_publisher --x {} --y {} --z {} --qx {} --qy {} --qz {} --qw {} --frame-id imu0 --child-frame-id {name} &\n",
            v.x, v.y, v.z, q[0], q[1], q[2], q[3]
        );
        yaml += &format!(
            "- parent: imu0\n  child: {name}\n  translation: [{}, {}, {}]\n  rotation: [{}, {}, {}, {}] # xyzw\n",
            v.x, v.y, v.z, q[0], q[1], q[2], q[3]
        );
    }
    sh += "wait\n";
    Ok(vec![
        ExportFile {
            name: "static_transforms.sh".into(),
            text: sh,
        },
        ExportFile {
            name: "static_transforms.yaml".into(),
            text: yaml,
        },
    ])
}
