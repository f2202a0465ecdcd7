//! The checker that every part of a manifest reports its problems through (the sections of
//! the manifest itself and, through [`super::SceneSection::check`], the tests' `scene:`
//! sections): finite numbers, ranges, lengths that hold two spacings, in field order.

/// One failed check: the dotted field path and what is wrong (without provenance).
#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    pub field: String,
    pub message: String,
    /// The value is NaN or infinite.
    pub non_finite: bool,
}

/// An interval bound check of an `f64`.
#[derive(Clone, Copy)]
pub enum Range {
    /// (lo, hi) with open/closed ends: `lo_closed`, `hi_closed`; `None` = unbounded.
    Between {
        lo: Option<(f64, bool)>,
        hi: Option<(f64, bool)>,
    },
}

/// Most spacings one scene length may span (2^24, far beyond any run that fits in memory):
/// the size estimate's first coarse build, at 2^20 spacings, then holds a few cells per
/// axis (a 1e19 m cone exhausted the memory there).
pub const MAX_SPACINGS_PER_LENGTH: f64 = 16_777_216.0;

pub const POSITIVE: Range = Range::Between {
    lo: Some((0.0, false)),
    hi: None,
};
pub const NON_NEGATIVE: Range = Range::Between {
    lo: Some((0.0, true)),
    hi: None,
};

pub fn between(lo: f64, lo_closed: bool, hi: f64, hi_closed: bool) -> Range {
    Range::Between {
        lo: Some((lo, lo_closed)),
        hi: Some((hi, hi_closed)),
    }
}

impl Range {
    fn contains(self, x: f64) -> bool {
        let Range::Between { lo, hi } = self;
        let lo_ok = match lo {
            None => true,
            Some((l, true)) => x >= l,
            Some((l, false)) => x > l,
        };
        let hi_ok = match hi {
            None => true,
            Some((h, true)) => x <= h,
            Some((h, false)) => x < h,
        };
        lo_ok && hi_ok
    }

    fn describe(self) -> String {
        let Range::Between { lo, hi } = self;
        match (lo, hi) {
            (Some((0.0, false)), None) => "must be > 0".to_string(),
            (Some((0.0, true)), None) => "must be >= 0".to_string(),
            (Some((l, false)), None) => format!("must be > {l:?}"),
            (Some((l, true)), None) => format!("must be >= {l:?}"),
            (None, Some((h, false))) => format!("must be < {h:?}"),
            (None, Some((h, true))) => format!("must be <= {h:?}"),
            (Some((l, lc)), Some((h, hc))) => format!(
                "must be in {}{}, {}{}",
                if lc { '[' } else { '(' },
                fmt_num(l),
                fmt_num(h),
                if hc { ']' } else { ')' }
            ),
            (None, None) => String::new(),
        }
    }
}

/// Short number formatting for messages: `1` not `1.0`, `1e-9` kept short.
pub fn fmt_num(x: f64) -> String {
    if x == x.trunc() && x.abs() < 1e15 {
        format!("{}", x as i64)
    } else {
        format!("{x:?}")
    }
}

/// Collects the issues of a manifest in field order (test modules check their `scene:`
/// sections through it).
#[derive(Default)]
pub struct Checker {
    issues: Vec<Issue>,
}

impl Checker {
    pub fn new() -> Self {
        Self { issues: Vec::new() }
    }
    /// No issue so far.
    pub fn is_clean(&self) -> bool {
        self.issues.is_empty()
    }
    /// The issues found, in the order they were reported.
    pub fn into_issues(self) -> Vec<Issue> {
        self.issues
    }
    pub fn fail(&mut self, field: &str, message: String) {
        self.issues.push(Issue {
            field: field.to_string(),
            message,
            non_finite: false,
        });
    }

    /// Finite and in `range`; returns whether it passed.
    pub fn real(&mut self, field: &str, x: f64, range: Range) -> bool {
        if !x.is_finite() {
            self.fail(field, format!("must be a finite number, got {x:?}"));
            if let Some(issue) = self.issues.last_mut() {
                issue.non_finite = true;
            }
            false
        } else if !range.contains(x) {
            self.fail(field, format!("{}, got {}", range.describe(), fmt_num(x)));
            false
        } else {
            true
        }
    }

    /// Each length must hold at least two particle spacings, and at most
    /// [`MAX_SPACINGS_PER_LENGTH`].
    pub fn lattice_lengths(&mut self, dims: &[(&str, f64)], spacing_m: f64) {
        for &(field, x) in dims {
            if x < 2.0 * spacing_m {
                self.fail(
                    field,
                    format!(
                        "must be >= 2 * spacing_m = {}, got {}",
                        fmt_num(2.0 * spacing_m),
                        fmt_num(x)
                    ),
                );
            } else if x > MAX_SPACINGS_PER_LENGTH * spacing_m {
                self.fail(
                    field,
                    format!(
                        "must be <= 2^24 * spacing_m = {}, got {}",
                        fmt_num(MAX_SPACINGS_PER_LENGTH * spacing_m),
                        fmt_num(x)
                    ),
                );
            }
        }
    }

    pub fn int_at_least(&mut self, field: &str, x: u64, min: u64) -> bool {
        if x < min {
            self.fail(field, format!("must be >= {min}, got {x}"));
            false
        } else {
            true
        }
    }
}
