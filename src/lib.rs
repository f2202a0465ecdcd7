pub mod build_info;
pub mod proto;
pub mod record;
