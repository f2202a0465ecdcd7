//! A test's surface profile against its closed form: the test measures it and writes its
//! table ([`super::Experiment::surface_profile`]); `runner profile` and the report draw it
//! without knowing which test it came from.

/// One labelled line of a figure (the report draws it as `report::plot::Series`).
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub label: String,
    /// (x, h) in metres.
    pub points: Vec<(f64, f64)>,
}

/// One state's free surface against the closed form: a table and the curves of a figure.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceProfile {
    /// A heading line with the test's summary figures, then one row per station.
    pub table: String,
    /// The figure's x axis (e.g. `"r [m]"`).
    pub x_label: &'static str,
    pub spacing_m: f64,
    pub time_s: f64,
    /// The measured surface.
    pub surface: Curve,
    /// The closed form for the measured front or radius (none without one, e.g. spheres).
    pub closed_at_measured: Option<Curve>,
    /// The closed form for the run's volume: its own front or radius.
    pub closed_for_volume: Option<Curve>,
}

/// What a cell of a [`CellMap`] shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fill {
    /// Concrete: a fluid particle within a spacing of the cell's centre.
    Concrete,
    /// Solid (a rock).
    Rock,
    /// Neither: void no concrete reached, or air.
    Empty,
}

/// A section of a state as square cells of one spacing (the report draws it): `cells` row by
/// row from the lower left, the first axis fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct CellMap {
    pub title: String,
    pub x_label: &'static str,
    pub y_label: &'static str,
    /// Lower-left corner of the map and the cells' size, metres.
    pub origin_m: (f64, f64),
    pub cell_m: f64,
    pub columns: usize,
    pub rows: usize,
    pub cells: Vec<Fill>,
}
