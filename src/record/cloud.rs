//! Packing particle frames into `foxglove.PointCloud`.

use crate::proto::foxglove::{
    PackedElementField, PointCloud, Pose, Quaternion, Vector3, packed_element_field::NumericType,
};

/// Frame id of every point cloud we write.
pub const FRAME_ID: &str = "world";

/// Builds a `foxglove.PointCloud` of `positions.len() / dimension` particles.
///
/// Each point is packed little-endian as `x, y, z` (FLOAT32, `z = 0` in 2D) followed by one
/// FLOAT32 per entry of `fields`, in the given order (e.g. `("speed_m_s", &speeds)`), so the
/// stride is `4 * (3 + fields.len())` bytes. `positions` is flattened particle-major
/// (`[x0, y0, (z0,) x1, ...]`). The pose is the identity, the frame `"world"`, and the
/// timestamp `time_ns` (simulation time).
///
/// # Panics
/// If `dimension` is not 2 or 3, if `positions.len()` is not a multiple of `dimension`, or if a
/// field does not have one value per particle (all programming errors).
pub fn point_cloud(
    time_ns: u64,
    dimension: usize,
    positions: &[f64],
    fields: &[(&str, &[f32])],
) -> PointCloud {
    assert!(
        dimension == 2 || dimension == 3,
        "point_cloud: dimension must be 2 or 3, got {dimension}"
    );
    assert!(
        positions.len().is_multiple_of(dimension),
        "point_cloud: {} coordinates are not a multiple of dimension {dimension}",
        positions.len()
    );
    let n = positions.len() / dimension;
    for (name, values) in fields {
        assert_eq!(
            values.len(),
            n,
            "point_cloud: field {name:?} has {} values for {n} particles",
            values.len()
        );
    }
    let per_point = 3 + fields.len();
    let stride = 4 * per_point;
    let mut packed = Vec::with_capacity(4 * 3 + 4 * fields.len());
    for (i, name) in ["x", "y", "z"]
        .into_iter()
        .chain(fields.iter().map(|(name, _)| *name))
        .enumerate()
    {
        packed.push(PackedElementField {
            name: name.to_string(),
            offset: (4 * i) as u32,
            r#type: NumericType::Float32 as i32,
        });
    }
    let mut data = Vec::with_capacity(n * stride);
    for p in 0..n {
        let xyz = &positions[p * dimension..(p + 1) * dimension];
        for k in 0..3 {
            let v = xyz.get(k).copied().unwrap_or(0.0) as f32;
            data.extend_from_slice(&v.to_le_bytes());
        }
        for (_, values) in fields {
            data.extend_from_slice(&values[p].to_le_bytes());
        }
    }
    PointCloud {
        timestamp: Some(timestamp(time_ns)),
        frame_id: FRAME_ID.to_string(),
        pose: Some(Pose {
            position: Some(Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.0,
            }),
            orientation: Some(Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }),
        }),
        point_stride: stride as u32,
        fields: packed,
        data,
    }
}

/// Nanoseconds since zero as a protobuf `Timestamp`.
pub fn timestamp(time_ns: u64) -> prost_types::Timestamp {
    prost_types::Timestamp {
        seconds: (time_ns / 1_000_000_000) as i64,
        nanos: (time_ns % 1_000_000_000) as i32,
    }
}
