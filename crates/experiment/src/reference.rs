//! The run's reference time. Every time an experiment reports is also given as a multiple of it:
//! the host's speed varies from day to day, and such ratios vary less than milliseconds do.

use anyhow::Result;
use fem::{SolverOptions, StaticSolver};
use mesh::stats::median;

use crate::fem_speed::reference_problem;
use crate::fmt;

/// Solves from rest timed when an experiment measures the reference alone (about 0.4 s): a
/// median of many, so that a passing load on the host moves it little.
const RUNS: usize = 21;

/// Measures the reference time (ms): the median of [`RUNS`] solves from rest of the reference
/// problem ([`reference_problem`]: the co-rotational standard 5k-tet liver phantom, the law and
/// element of the registration's FEM) on a new solver, after its first solve (which factorises
/// the rest tangent). `fem-speed` times the same case among its own.
pub(crate) fn measure() -> Result<f64> {
    let opts = SolverOptions::default();
    let mut solver = StaticSolver::new(reference_problem()?)?;
    solver.solve(&opts)?;
    let mut times = Vec::with_capacity(RUNS);
    for _ in 0..RUNS {
        times.push(mesh::stats::ms(solver.solve(&opts)?.timings.total));
    }
    Ok(median(&mut times))
}

/// " (N×)": `ms` over the reference time, to three significant digits; empty without one.
pub(crate) fn ratio(ms: f64, reference_ms: Option<f64>) -> String {
    match reference_ms {
        Some(r) if r > 0.0 => {
            let ratio = ms / r;
            let decimals = if ratio < 9.995 {
                2
            } else if ratio < 99.95 {
                1
            } else {
                0
            };
            format!(" ({ratio:.decimals$}×)")
        }
        _ => String::new(),
    }
}

/// `ms` with `digits` decimals and its multiple of the reference, e.g. "564.0 ms (39.2×)".
pub(crate) fn ms(ms: f64, digits: usize, reference_ms: Option<f64>) -> String {
    format!("{}{}", fmt(ms, digits, "ms"), ratio(ms, reference_ms))
}

/// `seconds` with `digits` decimals and its multiple of the reference, e.g. "2.4 s (96.0×)".
pub(crate) fn seconds(seconds: f64, digits: usize, reference_ms: Option<f64>) -> String {
    format!("{}{}", fmt(seconds, digits, "s"), ratio(1e3 * seconds, reference_ms))
}

/// What "(N×)" means, for an experiment's notes.
pub(crate) fn note(reference_ms: Option<f64>) -> String {
    format!(
        "(N×): the time over the reference, the co-rotational standard 5k liver's median solve from rest in the same \
         run{}: the host's speed varies from day to day, and such ratios vary less than milliseconds do, on a quiet \
         host.",
        reference_ms.map_or(String::new(), |r| format!(" ({})", fmt(r, 1, "ms")))
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_carry_their_multiple_of_the_reference_to_three_digits() {
        assert_eq!(ms(564.0, 1, Some(14.4)), "564.0 ms (39.2×)");
        assert_eq!(ms(7.2, 1, Some(14.4)), "7.2 ms (0.50×)");
        assert_eq!(ms(7.2, 1, None), "7.2 ms");
        assert_eq!(ms(143.9, 0, Some(14.4)), "144 ms (9.99×)");
        assert_eq!(ms(3715.0, 0, Some(28.1)), "3715 ms (132×)");
        assert_eq!(seconds(2.4, 1, Some(25.0)), "2.4 s (96.0×)");
        assert_eq!(seconds(2.4, 1, None), "2.4 s");
        assert!(note(Some(24.06)).contains("run (24.1 ms)"), "{}", note(Some(24.06)));
    }
}
