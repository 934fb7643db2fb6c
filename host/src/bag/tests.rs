//! Unit tests of the wire readers, the per-point time rules and the image conversion.

use super::cloud::{convert_cloud, PointTime, TimeUnit};
use super::error::DecodeError;
use super::image::{convert_compressed, convert_image, ImageOut};
use super::msgs::{CompressedImageMsg, ImageMsg, PointCloud2Msg, PointField};
use super::wire::{Dialect, Header, WireReader};

type TestResult = Result<(), Box<dyn std::error::Error>>;

const STAMP: u64 = 1_700_000_000_123_456_789;

#[test]
fn cdr_aligns_eight_byte_values_from_the_encapsulation_end() -> TestResult {
    // CDR_LE: u8 at 0, 7 bytes padding, f64 at 8 (relative to byte 4 of the buffer)
    let mut data = vec![0x00, 0x01, 0x00, 0x00, 7];
    data.extend([0xAA; 7]);
    data.extend(2.5f64.to_le_bytes());
    let mut r = WireReader::new(&data, Dialect::Cdr)?;
    assert_eq!((r.u8()?, r.f64()?), (7, 2.5));
    // XCDR2 aligns 8-byte values to 4 only
    let mut data = vec![0x00, 0x07, 0x00, 0x00, 7, 0, 0, 0];
    data.extend(2.5f64.to_le_bytes());
    let mut r = WireReader::new(&data, Dialect::Cdr)?;
    assert_eq!((r.u8()?, r.f64()?), (7, 2.5));
    // Big endian
    let mut data = vec![0x00, 0x00, 0x00, 0x00];
    data.extend(513u32.to_be_bytes());
    assert_eq!(WireReader::new(&data, Dialect::Cdr)?.u32()?, 513);
    Ok(())
}

#[test]
fn headers_differ_between_ros1_and_cdr() -> TestResult {
    let mut ros1 = 9u32.to_le_bytes().to_vec(); // seq
    ros1.extend(1u32.to_le_bytes());
    ros1.extend(5u32.to_le_bytes());
    ros1.extend(3u32.to_le_bytes());
    ros1.extend(b"imu");
    let mut cdr = vec![0x00, 0x01, 0x00, 0x00];
    cdr.extend(1u32.to_le_bytes());
    cdr.extend(5u32.to_le_bytes());
    cdr.extend(4u32.to_le_bytes());
    cdr.extend(b"imu\0");
    let expected = Header {
        stamp_ns: 1_000_000_005,
        frame_id: "imu".into(),
    };
    assert_eq!(WireReader::new(&ros1, Dialect::Ros1)?.header()?, expected);
    assert_eq!(WireReader::new(&cdr, Dialect::Cdr)?.header()?, expected);
    Ok(())
}

#[test]
fn unknown_cdr_representation_and_truncation_are_typed() {
    let err = WireReader::new(&[0x00, 0x03, 0, 0], Dialect::Cdr).err();
    assert!(matches!(
        err,
        Some(DecodeError::CdrRepresentation { id: 3 })
    ));
    let err = WireReader::new(&[1, 2], Dialect::Ros1).and_then(|mut r| r.u32());
    assert!(matches!(
        err,
        Err(DecodeError::Truncated {
            at: 0,
            need: 4,
            len: 2
        })
    ));
}

/// A cloud of `x y z` FLOAT32 plus one time field of `datatype` holding `times`.
fn cloud_bytes(times: &[f64], datatype: u8) -> (Vec<PointField>, Vec<u8>, u32) {
    let time_size = if datatype == 8 { 8 } else { 4 };
    let step = 12 + time_size;
    let mut data = Vec::new();
    for (i, &t) in times.iter().enumerate() {
        for c in [1.0 + i as f32, 2.0, 3.0] {
            data.extend(c.to_le_bytes());
        }
        match datatype {
            6 => data.extend((t as u32).to_le_bytes()),
            7 => data.extend((t as f32).to_le_bytes()),
            _ => data.extend(t.to_le_bytes()),
        }
    }
    let field = |name: &str, offset, datatype| PointField {
        name: name.into(),
        offset,
        datatype,
        count: 1,
    };
    let fields = vec![
        field("x", 0, 7),
        field("y", 4, 7),
        field("z", 8, 7),
        field(
            if datatype == 8 { "timestamp" } else { "time" },
            12,
            datatype,
        ),
    ];
    (fields, data, step as u32)
}

fn convert(times: &[f64], datatype: u8) -> Result<super::cloud::Scan, DecodeError> {
    let (fields, data, step) = cloud_bytes(times, datatype);
    let msg = PointCloud2Msg {
        header: Header::default(),
        height: 1,
        width: times.len() as u32,
        fields,
        is_bigendian: false,
        point_step: step,
        row_step: step * times.len() as u32,
        data: &data,
    };
    convert_cloud(&msg, STAMP)
}

#[test]
fn velodyne_relative_float_seconds_ending_at_the_stamp_restamp_the_scan() -> TestResult {
    // Velodyne: float32 s relative to a header stamp at the end of the sweep (negative)
    let scan = convert(&[-0.1, -0.05, 0.0], 7)?;
    let t: Vec<u32> = scan.cloud.points.iter().map(|p| p.t_ns).collect();
    let first = STAMP - ((-0.1f32) as f64 * -1e9).round() as u64;
    assert_eq!(scan.stamp_ns, first);
    assert_eq!(t[0], 0);
    assert!((f64::from(t[1]) - 5e7).abs() < 10.0 && (f64::from(t[2]) - 1e8).abs() < 10.0);
    assert_eq!(
        scan.time,
        PointTime::Field {
            name: "time".into(),
            unit: TimeUnit::Seconds,
            absolute: false
        }
    );
    Ok(())
}

#[test]
fn absolute_float64_seconds_and_nanoseconds_are_recognised() -> TestResult {
    // Hesai / Robosense: float64 s since the epoch, starting 1 ms after the header stamp
    let start_s = STAMP as f64 * 1e-9 + 1e-3;
    let scan = convert(&[start_s, start_s + 0.05], 8)?;
    assert!(matches!(
        scan.time,
        PointTime::Field {
            unit: TimeUnit::Seconds,
            absolute: true,
            ..
        }
    ));
    assert_eq!(scan.stamp_ns, STAMP);
    // 1 ms and 51 ms, to the ~240 ns resolution of f64 seconds near 1.7e9
    let t1 = f64::from(scan.cloud.points[0].t_ns);
    assert!((t1 - 1e6).abs() < 500.0, "{t1}");
    // Livox: float64 ns since the epoch
    let ns = STAMP as f64 + 2e6;
    let scan = convert(&[ns, ns + 1e8], 8)?;
    assert!(matches!(
        scan.time,
        PointTime::Field {
            unit: TimeUnit::Nanoseconds,
            absolute: true,
            ..
        }
    ));
    assert!((f64::from(scan.cloud.points[1].t_ns) - 1.02e8).abs() < 500.0);
    Ok(())
}

#[test]
fn relative_uint32_nanoseconds_keep_the_header_stamp() -> TestResult {
    // Ouster: uint32 ns from the header stamp (first firing), first return late
    let scan = convert(&[2_000.0, 50_000_000.0], 6)?;
    assert_eq!(scan.stamp_ns, STAMP);
    assert_eq!(scan.cloud.points[0].t_ns, 2_000);
    assert!(!scan.time_dropped);
    // A span over 1 s is a unit mistake: times dropped, flagged
    let scan = convert(&[0.0, 3_000_000_000.0], 6)?;
    assert!(scan.time_dropped);
    assert!(scan.cloud.points.iter().all(|p| p.t_ns == 0));
    Ok(())
}

#[test]
fn cloud_without_xyz_or_with_short_data_is_an_error() {
    let (mut fields, data, step) = cloud_bytes(&[0.0], 6);
    let mut msg = PointCloud2Msg {
        header: Header::default(),
        height: 1,
        width: 2,
        fields: fields.clone(),
        is_bigendian: false,
        point_step: step,
        row_step: 2 * step,
        data: &data,
    };
    assert!(matches!(
        convert_cloud(&msg, STAMP),
        Err(DecodeError::DataSize { .. })
    ));
    fields.retain(|f| f.name != "z");
    msg.fields = fields;
    msg.width = 1;
    assert!(matches!(
        convert_cloud(&msg, STAMP),
        Err(DecodeError::NoXyz)
    ));
}

fn image_msg<'a>(encoding: &str, width: u32, step: u32, data: &'a [u8]) -> ImageMsg<'a> {
    ImageMsg {
        header: Header::default(),
        height: 2,
        width,
        encoding: encoding.into(),
        is_bigendian: false,
        step,
        data,
    }
}

#[test]
fn raw_images_keep_their_pixels_and_row_padding_is_dropped() -> TestResult {
    // bgr8, 1 pixel wide, rows padded to 4 bytes
    let data = [1, 2, 3, 0, 4, 5, 6, 0];
    let ImageOut::Pixels(img) = convert_image(&image_msg("bgr8", 1, 4, &data))? else {
        return Err("expected pixels".into());
    };
    assert_eq!(img.to_rgb8().into_raw(), vec![3, 2, 1, 6, 5, 4]);
    let data = [0x34, 0x12, 0xff, 0xff];
    let ImageOut::Pixels(img) = convert_image(&image_msg("mono16", 1, 2, &data))? else {
        return Err("expected pixels".into());
    };
    assert_eq!(img.to_luma16().into_raw(), vec![0x1234, 0xffff]);
    let err = convert_image(&image_msg("yuv422", 1, 2, &data)).err();
    assert!(matches!(err, Some(DecodeError::ImageEncoding { .. })));
    let err = convert_image(&image_msg("mono8", 3, 3, &data)).err();
    assert!(matches!(err, Some(DecodeError::DataSize { .. })));
    Ok(())
}

#[test]
fn compressed_png_is_kept_and_unknown_formats_refused() -> TestResult {
    let mut png = Vec::new();
    image::GrayImage::from_raw(2, 1, vec![10, 20])
        .ok_or("image")?
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
    let msg = |format: &str, data| CompressedImageMsg {
        header: Header::default(),
        format: format.into(),
        data,
    };
    assert!(matches!(
        convert_compressed(&msg("mono8; png compressed ", &png))?,
        ImageOut::PngBytes(b) if b == png
    ));
    let err = convert_compressed(&msg("16UC1; compressedDepth", &png)).err();
    assert!(matches!(err, Some(DecodeError::CompressedFormat { .. })));
    let err = convert_compressed(&msg("jpeg", &png[..10])).err();
    assert!(matches!(err, Some(DecodeError::ImagePayload { .. })));
    Ok(())
}

#[test]
fn cloud_without_time_field_keeps_the_header_stamp_and_zero_offsets() -> TestResult {
    let (mut fields, data, step) = cloud_bytes(&[5.0, 6.0], 6);
    fields.retain(|f| f.name != "time");
    let msg = PointCloud2Msg {
        header: Header::default(),
        height: 1,
        width: 2,
        fields,
        is_bigendian: false,
        point_step: step,
        row_step: 2 * step,
        data: &data,
    };
    let scan = convert_cloud(&msg, STAMP)?;
    assert_eq!(scan.time, PointTime::Missing);
    assert_eq!(scan.stamp_ns, STAMP);
    assert_eq!(scan.cloud.len(), 2);
    assert!(scan.cloud.points.iter().all(|p| p.t_ns == 0));
    Ok(())
}

#[test]
fn gaps_over_three_median_intervals_are_reported_once_with_the_longest() {
    use super::warnings::{cadence, BagWarning};
    // 100 Hz with a 50 ms and a 100 ms hole
    let mut stamps: Vec<u64> = (0..50).map(|k| k * 10_000_000).collect();
    stamps.extend((0..50).map(|k| 540_000_000 + k * 10_000_000));
    stamps.extend((0..50).map(|k| 1_140_000_000 + k * 10_000_000));
    let mut warnings = Vec::new();
    let c = cadence("/imu", &stamps, &mut warnings);
    assert!((c.rate_hz - 100.0).abs() < 1e-9);
    let [BagWarning::Gaps {
        count,
        largest_s,
        at_s,
        ..
    }] = warnings.as_slice()
    else {
        panic!("expected one Gaps warning, got {warnings:?}");
    };
    assert_eq!(*count, 2);
    assert!((largest_s - 0.11).abs() < 1e-9 && (at_s - 1.03).abs() < 1e-9);
    // A regular stream raises nothing
    warnings.clear();
    cadence("/imu", &stamps[..50], &mut warnings);
    assert!(warnings.is_empty());
    // Over a 60 ms limit only the 110 ms interval counts
    super::warnings::long_intervals("/imu", &stamps, 60_000_000, &mut warnings);
    assert!(matches!(
        warnings.as_slice(),
        [BagWarning::ImuGapOverFilterLimit { count: 1, .. }]
    ));
}
