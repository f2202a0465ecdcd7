//! Figures of a test drawn once per stage (the rodding's strokes): the test names them, the
//! report samples its diagnostics at the start of every stage and draws them.

/// The figures and the table of a test whose run goes in stages.
#[derive(Debug, Clone, PartialEq)]
pub struct StagedFigures {
    /// The metric that counts the finished stages; the first diagnostics row at each of its
    /// values is that stage's sample.
    pub stage_metric: &'static str,
    /// The stage axis's label.
    pub stage_label: &'static str,
    /// Each figure: a title and its curves (metric, label).
    pub figures: Vec<StagedFigure>,
    /// The metrics of the per-stage table, in its column order.
    pub table: Vec<&'static str>,
}

/// One figure of [`StagedFigures`].
#[derive(Debug, Clone, PartialEq)]
pub struct StagedFigure {
    pub title: String,
    /// The value axis's label.
    pub y_label: &'static str,
    /// (metric, label) of each curve.
    pub curves: Vec<(&'static str, String)>,
    /// A horizontal reference line (value, label), e.g. a complete mix's share.
    pub reference: Option<(f64, String)>,
}
