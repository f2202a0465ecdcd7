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
