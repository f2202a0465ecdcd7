//! Generated protobuf types (see `proto/`) and the descriptor set MCAP schemas carry.

pub mod foxglove {
    include!(concat!(env!("OUT_DIR"), "/foxglove.rs"));
}
pub mod mps {
    pub mod v1 {
        include!(concat!(env!("OUT_DIR"), "/mps.v1.rs"));
    }
}

/// Serialized `FileDescriptorSet` of every file in `proto/` (imports included).
pub const DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/descriptors.bin"));
