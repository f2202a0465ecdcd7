pub mod build_info;
pub mod checkpoint;
pub mod manifest;
pub mod mps;
pub mod proto;
pub mod record;
pub mod run;
pub mod scene;
