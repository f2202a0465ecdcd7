//! The `/metrics` channel: each `/diagnostics` row's experiment metrics as the fields of one
//! message, so that a viewer plots a metric by a simple path (`/metrics.front_position_m`).
//! Foxglove and Lichtblick decode the `metrics` map of `/diagnostics` as a list of
//! `{key, value}` entries, which only a filter path reaches. The schema is made per run from
//! the metric names of its first row (the same in every row of a run): proto3 message
//! `mps.v1.run.Metrics`, `double time_s = 1`, then one `double` per metric from field 2 in
//! name order. Names that are not identifiers (none of ours) stay in the map only.
use std::collections::BTreeMap;

use prost::Message as _;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};

pub const TOPIC_METRICS: &str = "/metrics";
pub const SCHEMA_METRICS: &str = "mps.v1.run.Metrics";

/// The fields of a run's `/metrics` messages: metric name and field number.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricsLayout {
    fields: Vec<(String, u32)>,
}

fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl MetricsLayout {
    /// From a row's metric names (a map's keys: sorted, unique).
    pub fn new<'a>(names: impl IntoIterator<Item = &'a String>) -> Self {
        let fields = names
            .into_iter()
            .filter(|n| is_identifier(n) && n.as_str() != "time_s")
            .zip(2u32..)
            .map(|(n, k)| (n.clone(), k))
            .collect();
        Self { fields }
    }

    pub fn is_empty(&self) -> bool {
        self.fields.is_empty()
    }

    /// The schema record's data: a FileDescriptorSet holding the one message.
    pub fn descriptor_set(&self) -> Vec<u8> {
        let double = |name: &str, number: u32| FieldDescriptorProto {
            name: Some(name.to_string()),
            number: Some(number as i32),
            label: Some(Label::Optional as i32),
            r#type: Some(Type::Double as i32),
            json_name: Some(name.to_string()),
            ..Default::default()
        };
        let mut fields = vec![double("time_s", 1)];
        fields.extend(self.fields.iter().map(|(n, k)| double(n, *k)));
        let file = FileDescriptorProto {
            name: Some("mps/v1/run_metrics.proto".into()),
            package: Some("mps.v1.run".into()),
            message_type: vec![DescriptorProto {
                name: Some("Metrics".into()),
                field: fields,
                ..Default::default()
            }],
            syntax: Some("proto3".into()),
            ..Default::default()
        };
        FileDescriptorSet { file: vec![file] }.encode_to_vec()
    }

    /// One message: `time_s` and every metric of the layout that the row has, each as a
    /// 64-bit field (tag, then the value's 8 little-endian bytes), in field order.
    pub fn encode(&self, time_s: f64, metrics: &BTreeMap<String, f64>) -> Vec<u8> {
        let mut out = Vec::with_capacity(9 * (self.fields.len() + 1) + 8);
        let mut put = |number: u32, value: f64| {
            prost::encoding::encode_key(number, prost::encoding::WireType::SixtyFourBit, &mut out);
            out.extend_from_slice(&value.to_le_bytes());
        };
        put(1, time_s);
        for (name, number) in &self.fields {
            if let Some(v) = metrics.get(name) {
                put(*number, *v);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_that_are_not_identifiers_are_left_out() {
        let names: Vec<String> = ["a_m", "1x", "b-c", "time_s", "z_s"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let layout = MetricsLayout::new(&names);
        assert_eq!(
            layout.fields,
            [("a_m".to_string(), 2), ("z_s".to_string(), 3)]
        );
    }

    #[test]
    fn a_row_encodes_as_its_schema_says() {
        let row = BTreeMap::from([("a_m".to_string(), 0.25), ("b_s".to_string(), f64::NAN)]);
        let layout = MetricsLayout::new(row.keys());
        let bytes = layout.encode(1.5, &row);
        // Field 1 (key 0x09), field 2 (0x11), field 3 (0x19), each then 8 bytes.
        assert_eq!(bytes.len(), 27);
        assert_eq!((bytes[0], bytes[9], bytes[18]), (0x09, 0x11, 0x19));
        assert_eq!(f64::from_le_bytes(bytes[1..9].try_into().unwrap()), 1.5);
        assert_eq!(f64::from_le_bytes(bytes[10..18].try_into().unwrap()), 0.25);
        assert!(f64::from_le_bytes(bytes[19..27].try_into().unwrap()).is_nan());
        // The schema decodes and names the fields.
        let set = FileDescriptorSet::decode(&layout.descriptor_set()[..]).unwrap();
        let fields: Vec<_> = set.file[0].message_type[0]
            .field
            .iter()
            .map(|f| (f.name().to_string(), f.number()))
            .collect();
        assert_eq!(
            fields,
            [
                ("time_s".to_string(), 1),
                ("a_m".to_string(), 2),
                ("b_s".to_string(), 3)
            ]
        );
    }
}
