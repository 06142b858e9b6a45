//! The stability harness: every formula of every table kind driven through a matrix of extreme
//! inputs (g → ±1 and g = 0, μ and ξ at and next to their ends, tiny and huge orders), each row
//! stating what a correct result must satisfy. `voltab stability` prints the matrix; the test suite
//! asserts every row. Each kind keeps its rows in its own module; [`crate::registry::stability_rows`]
//! lists them all (this module names no kind, so the kinds below and above it can both use it).

use std::fmt;

/// What a row's value must satisfy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Expect {
    /// Finite.
    Finite,
    /// Finite and > 0.
    Positive,
    /// Finite and within [lo, hi].
    InRange(f64, f64),
    /// Finite and within `rel` relative error of `to`.
    Close {
        /// Expected value (from an analytic limit).
        to: f64,
        /// Relative tolerance.
        rel: f64,
    },
}

/// One evaluation.
#[derive(Debug, Clone)]
pub struct Row {
    /// Table kind or module.
    pub kind: &'static str,
    /// Formula evaluated.
    pub formula: &'static str,
    /// Inputs, readable.
    pub input: String,
    /// Result.
    pub value: f64,
    /// Requirement.
    pub expect: Expect,
}

impl Row {
    /// Whether the value meets the requirement.
    pub fn ok(&self) -> bool {
        let v = self.value;
        v.is_finite()
            && match self.expect {
                Expect::Finite => true,
                Expect::Positive => v > 0.0,
                Expect::InRange(lo, hi) => (lo..=hi).contains(&v),
                Expect::Close { to, rel } => (v - to).abs() <= rel * to.abs().max(f64::MIN_POSITIVE),
            }
    }
}

impl fmt::Display for Row {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} {:<10} {:<28} {:<36} = {:<24e} expect {:?}",
            if self.ok() { "ok  " } else { "FAIL" },
            self.kind,
            self.formula,
            self.input,
            self.value,
            self.expect
        )
    }
}
