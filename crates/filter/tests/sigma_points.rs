//! Simplex sigma points: weights, moments, exact reconstruction of a factored covariance; parameter transforms.

mod common;

use augsim_filter::{SimplexSigmaPoints, Transform};
use common::Rng;
use nalgebra::{DMatrix, DVector};

#[test]
fn simplex_weights_and_moments_are_exact() {
    for p in 1..=12 {
        let s = SimplexSigmaPoints::new(p).unwrap();
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
    assert!(SimplexSigmaPoints::new(0).is_err());
}

#[test]
fn sampling_reconstructs_mean_and_factored_covariance() {
    let mut rng = Rng::new(7);
    for (n, p) in [(1, 1), (5, 3), (8, 8), (20, 4)] {
        let s = SimplexSigmaPoints::new(p).unwrap();
        let mean = DVector::from_fn(n, |_, _| 100.0 * rng.normal());
        let l = DMatrix::from_fn(n, p, |_, _| rng.normal());
        let a = DMatrix::from_fn(p, p, |_, _| rng.normal());
        let u = &a * a.transpose() + DMatrix::identity(p, p) * 0.5;
        let x = s.sample(&mean, &l, &u).unwrap();
        assert_eq!((x.nrows(), x.ncols()), (n, p + 1));
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
    let s = SimplexSigmaPoints::new(2).unwrap();
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
