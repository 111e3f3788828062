//! Simplex and star sigma points: weights, moments, exact reconstruction of a factored covariance and of a linear
//! map's mean and covariance; parameter transforms.

mod common;

use augsim_filter::{SigmaPointSet, SigmaPoints, Transform};
use common::Rng;
use nalgebra::{DMatrix, DVector};

#[test]
fn simplex_weights_and_moments_are_exact() {
    for p in 1..=12 {
        let s = SigmaPoints::simplex(p).unwrap();
        assert_eq!(s.dim(), p);
        assert_eq!(s.count(), p + 1);
        let w = s.weights();
        assert_eq!(w.len(), p + 1);
        for wi in w {
            assert!((wi - 1.0 / (p + 1) as f64).abs() < 1e-16);
        }
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        let v = s.points();
        let mut first = DVector::zeros(p);
        let mut second = DMatrix::zeros(p, p);
        for (i, col) in v.column_iter().enumerate() {
            first += w[i] * col;
            second += w[i] * col * col.transpose();
            // A regular simplex centred at the origin: every point has squared norm trace(I_p) = p.
            assert!((col.norm_squared() - p as f64).abs() < 1e-12 * p as f64, "p={p} point {i}");
        }
        assert!(first.amax() < 1e-14, "p={p}: first moment {first}");
        assert!((second - DMatrix::<f64>::identity(p, p)).amax() < 1e-13, "p={p}: second moment");
    }
    assert!(SigmaPoints::simplex(0).is_err());
}

/// Every set under test for dimension p: simplex, star (κ = ½), and star with Julier's κ = 3 − p (a negative
/// centre weight for p > 3) and with κ = 0 (no centre weight).
fn all_sets(p: usize) -> Vec<SigmaPoints> {
    vec![
        SigmaPoints::simplex(p).unwrap(),
        SigmaPoints::star(p).unwrap(),
        SigmaPoints::star_with_kappa(p, 3.0 - p as f64).unwrap(),
        SigmaPoints::star_with_kappa(p, 0.0).unwrap(),
    ]
}

/// Weighted first and second moments of the columns of `x`.
fn moments(x: &DMatrix<f64>, w: &[f64]) -> (DVector<f64>, DMatrix<f64>) {
    let mut mean = DVector::zeros(x.nrows());
    for (i, col) in x.column_iter().enumerate() {
        mean += w[i] * col;
    }
    let mut cov = DMatrix::zeros(x.nrows(), x.nrows());
    for (i, col) in x.column_iter().enumerate() {
        let d = col - &mean;
        cov += w[i] * &d * d.transpose();
    }
    (mean, cov)
}

#[test]
fn star_weights_and_moments_are_exact() {
    for p in 1..=12 {
        let s = SigmaPoints::star(p).unwrap();
        assert_eq!(s.set(), SigmaPointSet::Star);
        assert_eq!((s.dim(), s.count()), (p, 2 * p + 1));
        assert_eq!(SigmaPointSet::Star.count(p), 2 * p + 1);
        // κ = ½: every weight is 1/(2p+1), the centre first, then ±√(p+½) on every axis.
        for wi in s.weights() {
            assert!((wi - 1.0 / (2 * p + 1) as f64).abs() < 1e-16, "p={p}");
        }
        let v = s.points();
        assert!(v.column(0).amax() == 0.0);
        for j in 0..p {
            let r = (p as f64 + 0.5).sqrt();
            assert_eq!(v[(j, 1 + j)], r);
            assert_eq!(v[(j, 1 + p + j)], -r);
            assert_eq!(v.column(1 + j).norm(), r);
        }
        for s in all_sets(p) {
            let w = s.weights();
            assert_eq!(w.len(), s.count());
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-14, "p={p} {:?}", s.set());
            // Σ α_i I(i) = 0 and P_α = Σ α_i I(i) I(i)^T = I_p: what the filter's update relies on.
            let (first, second) = moments(s.points(), w);
            assert!(first.amax() < 1e-14, "p={p}: first moment {first}");
            assert!((second - DMatrix::<f64>::identity(p, p)).amax() < 1e-13, "p={p}: second moment");
        }
    }
    assert!(SigmaPoints::star(0).is_err());
    assert!(SigmaPoints::star_with_kappa(3, -3.0).is_err());
    assert!(SigmaPoints::star_with_kappa(3, f64::NAN).is_err());
}

#[test]
fn sigma_point_sets_parse_by_name() {
    assert_eq!("simplex".parse::<SigmaPointSet>().unwrap(), SigmaPointSet::Simplex);
    assert_eq!("star".parse::<SigmaPointSet>().unwrap(), SigmaPointSet::Star);
    assert_eq!(SigmaPointSet::default(), SigmaPointSet::Simplex);
    let err = "cross".parse::<SigmaPointSet>().unwrap_err();
    assert!(err.contains("`cross`") && err.contains("simplex") && err.contains("star"), "{err}");
    for set in [SigmaPointSet::Simplex, SigmaPointSet::Star] {
        assert_eq!(set.to_string().parse::<SigmaPointSet>().unwrap(), set);
        assert_eq!(set.build(4).unwrap().set(), set);
    }
}

#[test]
fn linear_maps_are_reproduced_exactly_by_every_set() {
    // The unscented transform of y = A x + b: the weighted mean and covariance of the mapped sigma points are the
    // exact A x̂ + b and A P A^T, for the factored P = L U^{-1} L^T that the filter keeps.
    let mut rng = Rng::new(31);
    for (n, p, q) in [(1, 1, 1), (4, 2, 3), (6, 6, 2), (9, 3, 7)] {
        let mean = DVector::from_fn(n, |_, _| 10.0 * rng.normal());
        let l = DMatrix::from_fn(n, p, |_, _| rng.normal());
        let c = DMatrix::from_fn(p, p, |_, _| rng.normal());
        let u = &c * c.transpose() + DMatrix::identity(p, p) * 0.3;
        let a = DMatrix::from_fn(q, n, |_, _| rng.normal());
        let b = DVector::from_fn(q, |_, _| rng.normal());
        let p_x = &l * u.clone().try_inverse().unwrap() * l.transpose();
        let want_mean = &a * &mean + &b;
        let want_cov = &a * &p_x * a.transpose();
        for s in all_sets(p) {
            let x = s.sample(&mean, &l, &u).unwrap();
            assert_eq!(x.ncols(), s.count());
            let mut y = &a * &x;
            for mut col in y.column_iter_mut() {
                col += &b;
            }
            let (m, cov) = moments(&y, s.weights());
            let tol = 1e-11 * (1.0 + want_mean.amax());
            assert!((&m - &want_mean).amax() < tol, "mean n={n} p={p} {:?}", s.set());
            assert!((&cov - &want_cov).amax() < 1e-10 * want_cov.amax(), "cov n={n} p={p} {:?}", s.set());
        }
    }
}

#[test]
fn sampling_reconstructs_mean_and_factored_covariance() {
    let mut rng = Rng::new(7);
    for ((n, p), s) in [(1, 1), (5, 3), (8, 8), (20, 4)]
        .into_iter()
        .flat_map(|(n, p)| all_sets(p).into_iter().map(move |s| ((n, p), s)))
    {
        let mean = DVector::from_fn(n, |_, _| 100.0 * rng.normal());
        let l = DMatrix::from_fn(n, p, |_, _| rng.normal());
        let a = DMatrix::from_fn(p, p, |_, _| rng.normal());
        let u = &a * a.transpose() + DMatrix::identity(p, p) * 0.5;
        let x = s.sample(&mean, &l, &u).unwrap();
        assert_eq!((x.nrows(), x.ncols()), (n, s.count()));
        let w = s.weights();
        let mut m = DVector::zeros(n);
        for (i, col) in x.column_iter().enumerate() {
            m += w[i] * col;
        }
        assert!((&m - &mean).amax() < 1e-12 * mean.amax(), "mean n={n} p={p}");
        let mut cov = DMatrix::zeros(n, n);
        for (i, col) in x.column_iter().enumerate() {
            let d = col - &mean;
            cov += w[i] * &d * d.transpose();
        }
        let expected = &l * u.clone().try_inverse().unwrap() * l.transpose();
        assert!((&cov - &expected).amax() < 1e-10 * expected.amax(), "cov n={n} p={p}");
    }
}

#[test]
fn sampling_rejects_bad_factors() {
    for s in all_sets(2) {
        sampling_rejects_bad_factors_of(&s);
    }
}

fn sampling_rejects_bad_factors_of(s: &SigmaPoints) {
    let mean = DVector::zeros(3);
    let l = DMatrix::identity(3, 2);
    let indefinite = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
    assert!(s.sample(&mean, &l, &indefinite).is_err());
    let nan = DMatrix::from_row_slice(2, 2, &[1.0, f64::NAN, f64::NAN, 1.0]);
    assert!(s.sample(&mean, &l, &nan).is_err());
    assert!(s.sample(&mean, &DMatrix::identity(3, 3), &DMatrix::identity(2, 2)).is_err());
    assert!(s.sample(&mean, &l, &DMatrix::identity(3, 3)).is_err());
}

#[test]
fn transforms_map_round_trip_and_differentiate() {
    for t in [Transform::Identity, Transform::Exp, Transform::Abs] {
        for v in [-2.5, -0.3, 0.7, 3.0] {
            let phys = t.to_physical(v);
            if t != Transform::Identity {
                assert!(phys >= 0.0);
            }
            let back = t.to_filter(phys).unwrap();
            assert!((t.to_physical(back) - phys).abs() < 1e-14 * phys.abs().max(1.0));
            let h = 1e-6;
            let fd = (t.to_physical(v + h) - t.to_physical(v - h)) / (2.0 * h);
            assert!((fd - t.derivative(v)).abs() < 1e-6 * fd.abs().max(1.0), "{t:?} at {v}");
        }
    }
    assert_eq!(Transform::Abs.to_physical(-4.0), 4.0);
    assert!(Transform::Exp.to_filter(0.0).is_err());
    assert!(Transform::Abs.to_filter(-1.0).is_err());
    assert!(Transform::Identity.to_filter(f64::NAN).is_err());
}
