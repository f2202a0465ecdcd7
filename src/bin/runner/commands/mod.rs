//! One module per command or group of commands. Each handler takes its parsed options
//! (`cli`), does its work through the library, prints what it made, and returns how it ended
//! (`error::Result`); none prints its own error or picks an exit code.

pub mod bench;
pub mod calibrate;
pub mod figures;
pub mod files;
pub mod manifest;
pub mod resume;
pub mod run;
pub mod sweep;
pub mod verify;
