//! A configuration value refused: the table it is in and what is wrong.
//!
//! Every part of the core checks its own configuration and names the table
//! it was given (`core.track`, `core.fuse.conflict`), so the daemon reports
//! each problem where the operator wrote it, and all of them at once rather
//! than the first. The type lives here, not in the daemon, because the core
//! is where most values are checked and a library caller wants them typed
//! too.

/// One value refused.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// As the configuration file shows it: `[service]`, `[core.track]`,
    /// `[[input]] 2`, `[[receiver]] 1 (rx1)`.
    pub table: String,
    /// What is wrong, naming the field (`stats_interval_s = -1 must be
    /// positive`).
    pub message: String,
}

impl Problem {
    /// A problem in the table shown as `table`.
    pub fn new(table: &str, message: impl Into<String>) -> Problem {
        Problem { table: table.to_string(), message: message.into() }
    }

    /// A problem in the table at `path` (`core.track` is `[core.track]`).
    pub fn at(path: &str, message: impl Into<String>) -> Problem {
        Problem { table: format!("[{path}]"), message: message.into() }
    }
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // An array's entry is named by its number: a colon sets it apart.
        let sep = if self.table.starts_with("[[") { ": " } else { " " };
        write!(f, "{}{sep}{}", self.table, self.message)
    }
}

/// Checks that each named value is finite and positive.
pub fn positive(path: &str, values: &[(&str, f64)], out: &mut Vec<Problem>) {
    for &(name, v) in values {
        if !(v.is_finite() && v > 0.0) {
            out.push(Problem::at(path, format!("{name} = {v} must be positive")));
        }
    }
}

/// Checks that each named value is finite and zero or positive.
pub fn not_negative(path: &str, values: &[(&str, f64)], out: &mut Vec<Problem>) {
    for &(name, v) in values {
        if !(v.is_finite() && v >= 0.0) {
            out.push(Problem::at(path, format!("{name} = {v} must be zero or positive")));
        }
    }
}
