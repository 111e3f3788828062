//! Small statistics shared by the crates (the one median, mean and maximum, and durations in
//! milliseconds).

/// The median of `values`, reordering them: the middle value in `f64::total_cmp` order for an odd
/// count, the mean of the two middle values for an even one. NaNs count as the largest values (a
/// negative NaN as the smallest), as `total_cmp` orders them; an empty list gives NaN. Linear time
/// (`select_nth_unstable_by`).
pub fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mid = values.len() / 2;
    let odd = values.len() % 2 == 1;
    let (lower, &mut upper, _) = values.select_nth_unstable_by(mid, f64::total_cmp);
    match lower.iter().copied().max_by(f64::total_cmp) {
        Some(below) if !odd => 0.5 * (below + upper),
        _ => upper,
    }
}

/// The `q`-th percentile (0–100] of `values` by nearest rank: the smallest value with at least
/// q % of the values at or below it (`q = 50` of four values is the second, where the median
/// averages the second and the third). NaN when there are none.
pub fn percentile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len();
    sorted[((q / 100.0 * n as f64).ceil() as usize).clamp(1, n) - 1]
}

/// The arithmetic mean of `values`; NaN when there are none.
pub fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The largest of `values`, NaNs left out (`f64::max`); NaN when there are none.
pub fn max(values: &[f64]) -> f64 {
    values.iter().copied().fold(f64::NAN, f64::max)
}

/// A duration in milliseconds, as reports give times.
pub fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

#[cfg(test)]
mod tests {
    use super::{max, mean, median, ms, percentile};

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=20).rev().map(f64::from).collect();
        assert_eq!(percentile(&v, 95.0), 19.0);
        assert_eq!(percentile(&v, 100.0), 20.0);
        assert_eq!(percentile(&v, 50.0), 10.0);
        assert_eq!(percentile(&[7.0], 95.0), 7.0);
        assert!(percentile(&[], 95.0).is_nan());
    }

    #[test]
    fn mean_and_max_of_a_list_and_of_none() {
        assert_eq!(mean(&[1.0, 2.0, 6.0]), 3.0);
        assert_eq!(max(&[1.0, f64::NAN, 6.0, 2.0]), 6.0);
        assert!(mean(&[]).is_nan() && max(&[]).is_nan());
    }

    #[test]
    fn a_duration_in_milliseconds() {
        assert_eq!(ms(std::time::Duration::from_micros(1500)), 1.5);
        assert_eq!(ms(std::time::Duration::from_secs(2)), 2000.0);
    }

    #[test]
    fn the_median_is_the_middle_value_or_the_mean_of_the_two() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5, "even count: the mean of the middle values");
        assert_eq!(median(&mut [10.0, 2.0]), 6.0);
        assert_eq!(median(&mut [5.0]), 5.0);
        assert!(median(&mut []).is_nan());
        // NaN counts as the largest value.
        assert_eq!(median(&mut [f64::NAN, 1.0, 2.0]), 2.0);
        assert!(median(&mut [f64::NAN, f64::NAN, 1.0]).is_nan());
    }
}
