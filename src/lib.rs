pub mod build_info;
pub mod mps;
pub mod proto;
pub mod record;
pub mod scene;
