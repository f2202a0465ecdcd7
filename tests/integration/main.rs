//! The integration tests, as one test binary (`cargo test --release --test integration`;
//! one file's tests: `... --test integration lb_box::`). One binary instead of one per file:
//! in a release build every test crate compiles its own copy of the solver's generic code
//! (2D and 3D) and links the library again, which cost about 10 minutes of CPU per clean
//! build for 38 files; here that happens once.

mod common;
mod core_setup;

mod bad_input;
mod bench_suite;
mod bingham;
mod bodies;
mod boundaries;
mod calibrate;
mod cli;
mod column_collapse;
mod dam_break;
mod damaged_files;
mod determinism;
mod faults;
mod foxglove;
mod golden;
mod inclined_layer;
mod info;
mod inlets;
mod l_flow;
mod lb_box;
mod manifest;
mod mutations;
mod operators;
mod quiet_core;
mod record;
mod report;
mod resume;
mod rockfill;
mod rodding;
mod shapes;
mod slip;
mod slump;
mod sweep;
mod symmetry;
mod tags;
mod tank_at_rest;
mod trend;
mod verify;
mod yield_solve;
