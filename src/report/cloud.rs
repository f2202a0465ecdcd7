//! Decoding a `foxglove.PointCloud` back into columns.

use std::collections::BTreeMap;

use crate::proto::foxglove::{PointCloud, packed_element_field::NumericType};

/// One point-cloud frame as columns.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Frame {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    /// All zero for 2D runs.
    pub z: Vec<f32>,
    /// Every other FLOAT32 field by name (`kind`, `speed_m_s`, `flowing`, ...).
    pub fields: BTreeMap<String, Vec<f32>>,
}

impl Frame {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Decode a cloud whose fields are all FLOAT32 (what the recorder writes).
    pub fn decode(pc: &PointCloud) -> Result<Frame, String> {
        let stride = pc.point_stride as usize;
        if stride == 0 {
            return Err("point stride 0".into());
        }
        if !pc.data.len().is_multiple_of(stride) {
            return Err(format!(
                "{} data bytes are not a multiple of the stride {stride}",
                pc.data.len()
            ));
        }
        let n = pc.data.len() / stride;
        let mut columns: BTreeMap<String, Vec<f32>> = BTreeMap::new();
        for f in &pc.fields {
            if f.r#type != NumericType::Float32 as i32 {
                return Err(format!("field {:?} is not FLOAT32", f.name));
            }
            let offset = f.offset as usize;
            if offset + 4 > stride {
                return Err(format!("field {:?} lies outside the point", f.name));
            }
            let column = (0..n)
                .map(|p| {
                    let at = p * stride + offset;
                    f32::from_le_bytes(pc.data[at..at + 4].try_into().expect("4 bytes"))
                })
                .collect();
            columns.insert(f.name.clone(), column);
        }
        let mut take = |name: &str| columns.remove(name);
        let (Some(x), Some(y)) = (take("x"), take("y")) else {
            return Err("no x and y fields".into());
        };
        let z = take("z").unwrap_or_else(|| vec![0.0; n]);
        Ok(Frame {
            x,
            y,
            z,
            fields: columns,
        })
    }
}
