pub mod mps;
pub mod proto;
pub mod scene;
