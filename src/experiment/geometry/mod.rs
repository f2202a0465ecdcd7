//! Geometry shared by the tests: the cell-centred lattice and walls of wall and dummy layers.
pub mod container;
pub mod lattice;
pub mod shapes;
