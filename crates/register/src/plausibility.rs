//! Whether a cloud can be the organ at all, and whether a registration's result is believable:
//! a cloud that spans many times the organ (millimetres given for metres, random points) or a
//! tiny fraction of it (metres given for millimetres) is refused; a result whose registered surface stays far from the cloud or
//! whose organ moves by more than half its size is flagged, with what to try.

use mesh::length::{mm, LengthUnit, UnitMistake};
use mesh::{Point, SurfaceBvh};
use rayon::prelude::*;

use crate::{Organ, RegisterError, Result};

/// A cloud may span at most this many times the organ's extent (a partial view spans less).
pub const MAX_EXTENT_RATIO: f64 = 5.0;
/// ... and at least this fraction of it (a camera's view of a few centimetres of the organ).
pub const MIN_EXTENT_RATIO: f64 = 0.01;
/// A cloud spanning less than this fraction of the organ's extent is flagged: so small a view
/// leaves most of the deformation undetermined, and it is what centimetres read as millimetres
/// make of a view (a laparoscope's spans a third of a liver or more).
pub const SMALL_VIEW: f64 = 0.1;
/// A cloud read in its right unit and frame lies within this fraction of the organ's size of its
/// rest surface (median distance): a view deforms by less. What tells millimetres taken for metres,
/// and RAS taken for LPS.
pub const REST_FIT: f64 = 0.03;
/// At most this many of a cloud's points tell whether it lies on the organ in the other frame.
const MIX_UP_POINTS: usize = 256;
/// A cloud point farther than this (m) from the registered surface is not fitted: several times a
/// depth camera's noise.
pub const FAR_DISTANCE: f64 = 0.005;
/// A result leaving more than this share of the cloud's points unfitted is flagged (a camera's
/// outliers are a few per cent).
pub const SUSPECT_FAR_SHARE: f64 = 0.2;
/// A cloud of fewer points is flagged: a few points leave the organ's deformation undetermined.
pub const FEW_POINTS: usize = 10;
/// An organ moved by more than this fraction of its extent is flagged.
pub const SUSPECT_MOTION: f64 = 0.5;
/// A cell whose volume changes by more than this fraction is distorted: tissue this nearly
/// incompressible changes its volume by a few per cent where it is pressed hardest.
pub const DISTORTED_CELL: f64 = 0.3;
/// A result with more than this share of the organ's volume in distorted cells is flagged. On the
/// pushes of `register --demo` (1.5 to 6 N) the FEMs distort at most 5 %, the learned models at
/// most 18 % (the reduced-order model at 6 N); a cloud turned by 180° (RAS for LPS) registered by
/// the reduced-order model, whose surface fits it, distorts 38 %.
pub const SUSPECT_DISTORTED_SHARE: f64 = 0.3;
/// A result whose organ changes its volume by more than this fraction in all is flagged (the
/// demo's pushes: at most 14 %; a cloud scaled by half or 1.5: 68 % and 147 %).
pub const SUSPECT_VOLUME_CHANGE: f64 = 0.25;

/// How the displacement `u` changes the organ's volume: its volume after over before, and the
/// share of its volume in cells whose volume changes by more than [`DISTORTED_CELL`] (inverted
/// ones included); an immersed grid's cells count by their share of material.
pub fn volume_change(organ: &Organ, u: &[f64]) -> (f64, f64) {
    let mesh = organ.mesh();
    let (mut before, mut after, mut distorted) = (0.0, 0.0, 0.0);
    for i in 0..mesh.cells.len() {
        let share = mesh.cell_fraction.as_ref().map_or(1.0, |f| f[i]);
        let (v0, v1) = (mesh.cell_volume(i), mesh.displaced_cell_volume(i, u));
        before += share * v0;
        after += share * v1;
        if (v1 / v0 - 1.0).abs() > DISTORTED_CELL {
            distorted += share * v0;
        }
    }
    (after / before, distorted / before)
}

/// The extent of a point set: the diagonal of its box between the 2nd and 98th percentiles on
/// each axis (a few stray points do not count).
fn robust_extent(points: &[Point]) -> f64 {
    let mut sum = 0.0;
    for d in 0..3 {
        let mut c: Vec<f64> = points.iter().map(|p| p[d]).collect();
        c.sort_unstable_by(f64::total_cmp);
        let at = |q: f64| c[((c.len() - 1) as f64 * q).round() as usize];
        sum += (at(0.98) - at(0.02)).powi(2);
    }
    sum.sqrt()
}

/// Refuses an empty or damaged cloud ([`crate::check_cloud`]) and one whose extent cannot be a view
/// of the organ, saying what it probably is; returns the cloud's extent over the organ's.
pub fn check_extent(organ: &Organ, cloud: &[Point]) -> Result<f64> {
    crate::checks::check_cloud(cloud)?;
    let (size, extent) = (organ.extent(), robust_extent(cloud));
    let ratio = extent / size;
    if ratio > MAX_EXTENT_RATIO {
        let hint = if looks_like_millimetres(organ, cloud) {
            " Is it in millimetres? Divided by 1000 it lies on the organ's surface: its numbers are 1000 times the \
             unit it was read in (mm read as m: give its unit as mm, --units mm, units=\"mm\" in Python; µm read as \
             mm: convert them to mm)."
        } else {
            " It cannot be a view of the organ: wrong units, or not the organ's points."
        };
        return Err(RegisterError::Invalid(format!(
            "the cloud, as read, spans {extent:.1} m, {ratio:.0} times the organ's {:.0} mm (its box's diagonal).{hint}",
            mm(size)
        )));
    }
    if extent == 0.0 {
        return Err(RegisterError::Invalid(format!(
            "{} (its extent, 2nd to 98th percentile on each axis, is 0): it cannot be a view of the organ",
            match cloud.len() {
                1 => "the cloud is a single point".to_string(),
                n => format!("the cloud's {n} points lie at one place"),
            }
        )));
    }
    if ratio < MIN_EXTENT_RATIO {
        return Err(RegisterError::Invalid(format!(
            "the cloud spans {:.3e} mm, {ratio:.1e} of the organ's {:.0} mm (its box's diagonal): too small to be a \
             view of it (in metres, read as millimetres? give its unit as m: --units m, units=\"m\" in Python)",
            mm(extent),
            mm(size)
        )));
    }
    Ok(ratio)
}

/// Whether the cloud divided by 1000 is a view of the organ at rest: its extent within the
/// organ's, its median distance to the rest surface within [`REST_FIT`] of the organ's size.
fn looks_like_millimetres(organ: &Organ, cloud: &[Point]) -> bool {
    let metres: Vec<Point> = cloud.iter().map(|&p| LengthUnit::Millimetre.point_to_metres(p)).collect();
    let size = organ.extent();
    robust_extent(&metres) <= MAX_EXTENT_RATIO * size && median_distance(organ.rest_bvh(), &metres) < REST_FIT * size
}

/// The median distance of `cloud` to the surface of `bvh`.
fn median_distance(bvh: &SurfaceBvh, cloud: &[Point]) -> f64 {
    let mut distances: Vec<f64> = cloud.par_iter().map(|&c| bvh.distance(c)).collect();
    mesh::stats::median(&mut distances)
}

/// The warning for a cloud (as given, before any rigid pre-alignment) that lies on the organ at
/// rest with x and y negated, within [`REST_FIT`] of its size and at most half as far as it
/// does: RAS given for LPS or the reverse, which a rigid pre-alignment does not undo (a turn by
/// 180°, beyond its reach). `None` otherwise.
pub fn frame_mix_up(organ: &Organ, cloud: &[Point]) -> Option<String> {
    // The medians of evenly spread points: a fraction of a millisecond a frame.
    let sample: Vec<Point> = cloud.iter().step_by(cloud.len().div_ceil(MIX_UP_POINTS).max(1)).copied().collect();
    let negated: Vec<Point> = sample.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
    let bvh = organ.rest_bvh();
    let (given, other) = (median_distance(bvh, &sample), median_distance(bvh, &negated));
    (other < REST_FIT * organ.extent() && other <= 0.5 * given).then(|| {
        format!(
            "with x and y negated the cloud lies on the organ at rest (median distance {:.1} mm, against {:.1} mm as \
             given): is it in RAS where the organ is in LPS, or the reverse? Give its frame (--frame, frame= in \
             Python)",
            mm(other),
            mm(given)
        )
    })
}

/// Checks the targets' truth, `truth` (in the organ's frame and unit, as read): a truth lying on
/// average over [`TRUTH_ABSURD`] times the organ's size from the `targets` at rest is refused (no
/// error measured against it could mean anything), with the reading that brings it near when one
/// does. Otherwise the warning for a truth lying more than [`TRUTH_OFF`] of the organ's size from
/// them and at most a third as far read otherwise: with x and y negated (RAS given for LPS or the
/// reverse), or 1,000 or 10 times larger or smaller (metres given for millimetres, centimetres).
/// `None` otherwise (a truth in the cloud's own pose, under a rigid pre-alignment, is far either
/// way and not flagged).
pub fn check_truth(organ: &Organ, targets: &[Point], truth: &[Point]) -> Result<Option<String>> {
    let mix_up = truth_mix_up(organ, targets, truth);
    let given = mean_distance(targets, truth, false, 1.0);
    if given > TRUTH_ABSURD * organ.extent() {
        return Err(RegisterError::Invalid(match mix_up {
            Some(why) => format!("refused: {why}"),
            None => format!(
                "the truth lies {:.0} mm from the targets at rest on average, over {TRUTH_ABSURD:.0} times the organ's \
                 size ({:.0} mm): it cannot be their truth (its unit or frame?)",
                mm(given),
                mm(organ.extent())
            ),
        }));
    }
    Ok(mix_up)
}

/// The mean distance from `targets` to `truth`, read with x and y negated or not, and scaled.
fn mean_distance(targets: &[Point], truth: &[Point], negate: bool, scale: f64) -> f64 {
    let d = targets.iter().zip(truth).map(|(t, p)| {
        let p = if negate { [-p[0], -p[1], p[2]] } else { *p };
        mesh::norm(mesh::sub(p.map(|x| x * scale), *t))
    });
    d.sum::<f64>() / targets.len().max(1) as f64
}

/// The warning of [`check_truth`] for a truth that lies far nearer the targets read in another
/// frame or unit.
fn truth_mix_up(organ: &Organ, targets: &[Point], truth: &[Point]) -> Option<String> {
    // Each reading: x and y negated or not, a scale, and what it says.
    let read = |negate: bool, scale: f64| mean_distance(targets, truth, negate, scale);
    let given = read(false, 1.0);
    let frame = "is it in RAS where the targets are in LPS, or the reverse? Give its frame (a file that names it, or \
                 --frame)";
    let unit = |m: UnitMistake| {
        let (how, header) = (format!("read {}", m.undone_words()), format!("x_{}", m.given));
        (
            how,
            false,
            m.factor(),
            format!("was it {}? Give its unit (a header such as {header}, or --units)", m.question()),
        )
    };
    let readings = std::iter::once(("with x and y negated".to_string(), true, 1.0, frame.to_string()))
        .chain(UnitMistake::COMMON.map(unit));
    let reordered = reordered_distance(targets, truth).map(|d| {
        let question = "are its rows in another order than the targets'? Label both (a label column, or 3D \
                        Slicer's markups), or give them in one order";
        ("each matched to its nearest truth point".to_string(), d, question.to_string())
    });
    let (how, other, question) = readings
        .map(|(how, negate, scale, question)| (how, read(negate, scale), question))
        .chain(reordered)
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    (given > TRUTH_OFF * organ.extent() && other <= given / 3.0).then(|| {
        format!(
            "the truth lies {:.1} mm from the targets at rest on average, {:.1} mm {how}: {question}",
            mm(given),
            mm(other)
        )
    })
}

/// The mean distance from each target to its nearest point of `truth`, when those nearest points
/// are the truth's, each once, in another order than the targets' (its rows reordered); `None`
/// otherwise.
fn reordered_distance(targets: &[Point], truth: &[Point]) -> Option<f64> {
    if targets.len() != truth.len() {
        return None;
    }
    let nearest = |t: &Point| {
        (0..truth.len()).min_by(|&a, &b| mesh::distance(*t, truth[a]).total_cmp(&mesh::distance(*t, truth[b])))
    };
    let matched: Vec<usize> = targets.iter().map(nearest).collect::<Option<_>>()?;
    let mut taken = vec![false; truth.len()];
    if matched.iter().any(|&j| std::mem::replace(&mut taken[j], true))
        || matched.iter().enumerate().all(|(i, &j)| i == j)
    {
        return None;
    }
    let total: f64 = targets.iter().zip(&matched).map(|(t, &j)| mesh::distance(*t, truth[j])).sum();
    Some(total / targets.len() as f64)
}

/// The multiple of the organ's size (its box's diagonal) beyond which a truth is refused
/// ([`check_truth`]): a tracker's frame may lie a metre or two from the image's, not 26 m (on a
/// liver) as millimetres read as metres do.
pub const TRUTH_ABSURD: f64 = 100.0;

/// The share of the organ's size (its box's diagonal) beyond which a truth that lies far nearer
/// the targets at rest read in another frame or unit is flagged ([`check_truth`]): 15 mm on a
/// liver, about what a strong push moves its targets.
pub const TRUTH_OFF: f64 = 0.05;

/// The number of distinct points of `cloud`, counted up to `most` (a real cloud has that many
/// among its first points: the count stops there).
fn distinct_points(cloud: &[Point], most: usize) -> usize {
    let mut seen: Vec<Point> = Vec::with_capacity(most);
    for p in cloud {
        if seen.len() == most {
            break;
        }
        if !seen.contains(p) {
            seen.push(*p);
        }
    }
    seen.len()
}

/// The share of `distances` (cloud point to registered surface, m) beyond [`FAR_DISTANCE`].
pub fn far_share(distances: &[f64]) -> f64 {
    distances.iter().filter(|&&d| d > FAR_DISTANCE).count() as f64 / distances.len().max(1) as f64
}

/// What a registered frame says about itself ([`verdict`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Verdict {
    /// Why the result may not be believed; empty when it is plausible.
    pub warnings: Vec<String>,
    /// The registered organ changes its volume as tissue cannot (one of the warnings says so).
    pub distorted: bool,
    /// The cloud lies on the organ at rest with x and y negated ([`frame_mix_up`]; one of the
    /// warnings says so).
    pub other_frame: bool,
    /// The cloud spans under [`SMALL_VIEW`] of the organ (one of the warnings says so): a cloud in
    /// centimetres read as millimetres, or a view too small to tell the deformation.
    pub small_view: bool,
}

/// What a registered frame says about itself, given its cloud and that cloud's extent over the
/// organ's ([`check_extent`]), the share of the cloud left unfitted ([`far_share`]), its
/// displacement `u`, and whether it was rigidly pre-aligned. Without a pre-alignment, a frame
/// whose cloud lies on the organ in the other frame says so ([`frame_mix_up`]), rather than
/// advising one (a turn by 180° is beyond its reach).
pub fn verdict(organ: &Organ, u: &[f64], far_share: f64, (cloud, extent): (&[Point], f64), rigid: bool) -> Verdict {
    let points = distinct_points(cloud, FEW_POINTS);
    let size = organ.extent();
    let motion = u.chunks_exact(3).map(|d| mesh::norm([d[0], d[1], d[2]])).fold(0.0, f64::max);
    let mut out = Vec::new();
    let small_view = points >= FEW_POINTS && extent < SMALL_VIEW;
    if points < FEW_POINTS {
        out.push(format!(
            "the cloud has {points} distinct point(s), fewer than {FEW_POINTS}: so few leave the organ's \
             deformation undetermined"
        ));
    } else if small_view {
        out.push(format!(
            "the cloud spans {:.0} mm, {:.0} % of the organ's {:.0} mm (its box's diagonal): so small a view leaves \
             most of the deformation undetermined; if it is in centimetres, convert it to mm",
            extent * mm(size),
            100.0 * extent,
            mm(size)
        ));
    }
    let (volume, distorted_share) = volume_change(organ, u);
    let distorted = (volume - 1.0).abs() > SUSPECT_VOLUME_CHANGE || distorted_share > SUSPECT_DISTORTED_SHARE;
    let moved_too_far = motion > SUSPECT_MOTION * size;
    let far = far_share > SUSPECT_FAR_SHARE;
    // Asked of every frame: one warm-started from a good frame fits a cloud in the other frame
    // within a few iterations, undistorted (a FEM's, with its targets 29 mm off on the phantom).
    let mix_up = if rigid { None } else { frame_mix_up(organ, cloud) };
    if far {
        let hint = match (rigid, mix_up.is_some()) {
            (true, _) => {
                "; the rigid pre-alignment may have failed (the next cloud estimates it again), or the cloud is not \
                     the organ's"
            }
            (false, false) => "; if its frame is not the organ's, pre-align it (--rigid; rigid=True in Python)",
            (false, true) => "",
        };
        out.push(format!(
            "{:.0} % of the cloud stays more than {:.0} mm from the registered surface: the cloud does not fit the \
             organ{hint}",
            100.0 * far_share,
            mm(FAR_DISTANCE)
        ));
    }
    if distorted {
        out.push(format!(
            "the registered organ changes its volume by {:+.0} % in all, {:.0} % of it by more than {:.0} % locally: \
             tissue this nearly incompressible keeps its volume; the cloud may be in another frame (RAS for LPS), \
             unit or scale than the organ's, or not the organ's",
            100.0 * (volume - 1.0),
            100.0 * distorted_share,
            100.0 * DISTORTED_CELL
        ));
    }
    if moved_too_far {
        out.push(format!(
            "the organ moves by up to {:.0} mm, over half its size ({:.0} mm, its box's diagonal): not a plausible \
             deformation",
            mm(motion),
            mm(size)
        ));
    }
    let other_frame = mix_up.is_some();
    out.extend(mix_up);
    Verdict { warnings: out, distorted, other_frame, small_view }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A truth in the other frame (x and y negated), in another unit or in another order is named;
    /// a truth that moved as an organ does, or one far off in another way, is not.
    #[test]
    fn a_truth_in_the_other_frame_or_another_unit_is_named() {
        let at = [0.05, 0.12, -0.2];
        let organ = Organ::new(mesh::generate::box_tet(at, [0.2, 0.22, -0.12], [5, 3, 2]).unwrap(), None).unwrap();
        let targets = vec![[0.1, 0.15, -0.17], [0.15, 0.18, -0.15]];
        let moved: Vec<Point> = targets.iter().map(|p| [p[0] + 0.01, p[1], p[2] - 0.005]).collect();
        assert_eq!(truth_mix_up(&organ, &targets, &moved), None);
        let other: Vec<Point> = moved.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
        let w = truth_mix_up(&organ, &targets, &other).expect("named");
        assert!(w.contains("with x and y negated: is it in RAS"), "{w}");
        let shifted: Vec<Point> = targets.iter().map(|p| [p[0], p[1], p[2] + 0.3]).collect();
        assert_eq!(truth_mix_up(&organ, &targets, &shifted), None);
        // Metres read as millimetres: a thousand times too small.
        let in_metres: Vec<Point> = moved.iter().map(|p| p.map(|x| x * 1e-3)).collect();
        let w = truth_mix_up(&organ, &targets, &in_metres).expect("named");
        assert!(w.contains("read 1,000 times larger") && w.contains("given in m where mm"), "{w}");
        let in_cm: Vec<Point> = moved.iter().map(|p| p.map(|x| x * 10.0)).collect();
        assert!(truth_mix_up(&organ, &targets, &in_cm).expect("named").contains("read 10 times smaller"));
        // Its rows in the other order (no labels to pair them): named.
        let reversed: Vec<Point> = moved.iter().rev().copied().collect();
        let w = truth_mix_up(&organ, &targets, &reversed).expect("named");
        assert!(w.contains("mm each matched to its nearest truth point: are its rows in another order"), "{w}");
        // Near the z axis the other frame lies near too; a moderate push is not flagged.
        let central = vec![[0.004, 0.003, -0.17]];
        let pushed = vec![[0.004, 0.003, -0.19]];
        assert_eq!(truth_mix_up(&organ, &central, &pushed), None);
        // Checked: the warnings as they are; millimetres read as metres refused, saying so.
        assert_eq!(check_truth(&organ, &targets, &other).unwrap(), truth_mix_up(&organ, &targets, &other));
        let in_mm: Vec<Point> = moved.iter().map(|p| p.map(|x| x * 1e3)).collect();
        let refused = check_truth(&organ, &targets, &in_mm).unwrap_err().to_string();
        assert!(
            refused.contains("refused: the truth lies") && refused.contains("read 1,000 times smaller"),
            "{refused}"
        );
        // 40 m off an organ lying 100 m from the origin: no reading brings it near.
        let remote = Organ::new(mesh::generate::box_tet([100.0; 3], [100.2; 3], [2, 2, 2]).unwrap(), None).unwrap();
        let targets = [[100.1; 3]];
        let refused = check_truth(&remote, &targets, &[[140.1, 100.1, 100.1]]).unwrap_err().to_string();
        assert!(refused.contains("over 100 times the organ's size (346 mm): it cannot be their truth"), "{refused}");
    }

    /// A view of the organ passes; the same points in millimetres, in kilometres or all at one
    /// place are refused with what they probably are.
    #[test]
    fn clouds_that_cannot_be_a_view_are_refused_saying_why() {
        let organ = Organ::new(mesh::generate::box_tet([0.0; 3], [0.1, 0.06, 0.04], [5, 3, 2]).unwrap(), None).unwrap();
        let top: Vec<Point> = organ.mesh().nodes.iter().copied().filter(|p| p[2] > 0.039).collect();
        assert!(check_extent(&organ, &top).is_ok());
        let scaled = |s: f64| top.iter().map(|p| p.map(|c| s * c)).collect::<Vec<Point>>();
        let message = |cloud: &[Point]| check_extent(&organ, cloud).unwrap_err().to_string();
        assert!(message(&scaled(1e3)).contains("Is it in millimetres?"), "{}", message(&scaled(1e3)));
        assert!(message(&scaled(1e-3)).contains("too small to be a view"), "{}", message(&scaled(1e-3)));
        assert!(message(&scaled(1e6)).contains("not the organ's points"), "{}", message(&scaled(1e6)));
        let one_place = vec![[0.05, 0.03, 0.04]; 100];
        assert!(message(&one_place).starts_with("the cloud's 100 points lie at one place"), "{}", message(&one_place));
    }

    /// A view of a tenth of the organ (the same view in centimetres read as millimetres) is
    /// flagged; the whole view is not.
    #[test]
    fn a_view_of_a_tenth_of_the_organ_is_flagged() {
        let organ = Organ::new(mesh::generate::box_tet([0.0; 3], [0.1, 0.06, 0.04], [5, 3, 2]).unwrap(), None).unwrap();
        let top: Vec<Point> = organ.mesh().nodes.iter().copied().filter(|p| p[2] > 0.039).collect();
        let rest = vec![0.0; 3 * organ.mesh().num_nodes()];
        let flagged = |cloud: &[Point]| {
            verdict(&organ, &rest, 0.0, (cloud, check_extent(&organ, cloud).unwrap()), false).warnings
        };
        assert!(flagged(&top).is_empty(), "{:?}", flagged(&top));
        let centimetres: Vec<Point> = top.iter().map(|p| p.map(|c| 0.1 * c)).collect();
        let said = flagged(&centimetres);
        assert!(said.len() == 1 && said[0].contains("so small a view") && said[0].contains("centimetres"), "{said:?}");
    }

    /// A motion that keeps every cell's volume (a rotation, a shear) is not flagged; the organ
    /// shrunk to half its size, or a part of it squashed, is, with how much volume changed.
    #[test]
    fn a_registered_organ_that_changes_its_volume_is_flagged() {
        let organ = Organ::new(mesh::generate::box_tet([0.0; 3], [0.1, 0.06, 0.04], [5, 3, 2]).unwrap(), None).unwrap();
        let nodes = &organ.mesh().nodes;
        let top: Vec<Point> = nodes.iter().copied().filter(|p| p[2] > 0.039).collect();
        let judged = |u: &[f64]| verdict(&organ, u, 0.0, (&top, check_extent(&organ, &top).unwrap()), false);
        let flagged = |u: &[f64]| judged(u).warnings;
        let field = |f: &dyn Fn(Point) -> Point| -> Vec<f64> { nodes.iter().flat_map(|&p| f(p)).collect() };
        // A 30° turn about z and a shear of 0.3: volumes kept exactly.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let turn = field(&|p| [c * p[0] - s * p[1] - p[0], s * p[0] + c * p[1] - p[1], 0.0]);
        let shear = field(&|p| [0.3 * p[2], 0.0, 0.0]);
        for u in [&turn, &shear] {
            let (volume, distorted) = volume_change(&organ, u);
            assert!((volume - 1.0).abs() < 1e-12 && distorted == 0.0, "{volume} {distorted}");
            assert_eq!(judged(u), Verdict::default());
        }
        // Shrunk to half its size: an eighth of its volume, every cell distorted.
        let half = field(&|p| p.map(|x| -0.5 * x));
        let (volume, distorted) = volume_change(&organ, &half);
        assert!((volume - 0.125).abs() < 1e-12 && (distorted - 1.0).abs() < 1e-12, "{volume} {distorted}");
        let said = flagged(&half).join("; ");
        assert!(said.contains("changes its volume by -88 % in all, 100 % of it"), "{said}");
        assert!(judged(&half).distorted);
        // The nodes of its first two fifths along x brought to 60 % of their height: those fifths
        // squashed, the next one partly; the volume changes by −20 % in all (under the limit),
        // half of it by over 30 % (over the limit).
        let squash = field(&|p| [0.0, 0.0, if p[0] < 0.05 { -0.4 * p[2] } else { 0.0 }]);
        let (volume, distorted) = volume_change(&organ, &squash);
        assert!((volume - 0.8).abs() < 1e-12 && (distorted - 0.5).abs() < 1e-12, "{volume} {distorted}");
        assert!(flagged(&squash).join("; ").contains("changes its volume"), "{:?}", flagged(&squash));
        assert!(judged(&squash).distorted);
    }
}
