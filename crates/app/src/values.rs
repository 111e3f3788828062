//! Parsers of the numbers the command line takes: a value no run could use is refused as the
//! arguments are read, before any work.

/// A finite number for which `holds` is true; `what` says which numbers do, for the error.
fn number_where(text: &str, holds: impl Fn(f64) -> bool, what: &str) -> Result<f64, String> {
    let value: f64 = text.trim().parse().map_err(|e| format!("'{text}' is not a number: {e}"))?;
    match value.is_finite() && holds(value) {
        true => Ok(value),
        false => Err(format!("expected a finite number {what}, got {text}")),
    }
}

/// A number at least 0 (a standard deviation).
pub(crate) fn non_negative(text: &str) -> Result<f64, String> {
    number_where(text, |v| v >= 0.0, "at least 0")
}

/// A number above 0.
pub(crate) fn positive(text: &str) -> Result<f64, String> {
    number_where(text, |v| v > 0.0, "above 0")
}

/// A number at least 1.
pub(crate) fn at_least_one(text: &str) -> Result<f64, String> {
    number_where(text, |v| v >= 1.0, "at least 1")
}

/// A count of one or more (`--runs 0` is refused rather than run once).
pub fn count(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(0) => Err("expected a count of at least 1, got 0".into()),
        parsed => parsed.map_err(|e| format!("'{text}' is not a count (a whole number): {e}")),
    }
}

/// A factor in (0, 1].
pub(crate) fn factor(text: &str) -> Result<f64, String> {
    number_where(text, |v| v > 0.0 && v <= 1.0, "in (0, 1]")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_outside_their_range_are_refused_as_read() {
        assert_eq!(
            (non_negative("0"), positive("2.5"), at_least_one("1"), factor("1")),
            (Ok(0.0), Ok(2.5), Ok(1.0), Ok(1.0))
        );
        assert_eq!(non_negative("-1"), Err("expected a finite number at least 0, got -1".to_string()));
        assert!(
            factor("0").is_err() && factor("1.1").is_err() && positive("inf").is_err() && at_least_one("0.5").is_err()
        );
        assert_eq!(positive("x"), Err("'x' is not a number: invalid float literal".to_string()));
        assert_eq!((count("3"), count("0")), (Ok(3), Err("expected a count of at least 1, got 0".to_string())));
    }
}
