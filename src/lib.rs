pub mod manifest;
pub mod proto;
