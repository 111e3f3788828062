//! The lines the fronts print about a registration run and a comparison case: built here from the
//! domain's results, printed by the front.

use std::path::Path;

use fem::material::kpa;
use mesh::length::{mm, LengthUnit};
use mesh::stats::ms;
use register::{FrameOutcome, FrameSummary, Registration, RigidResult, RigidTransform, Summary};
use scenario::CaseScenario;

use crate::case::{Compared, SyntheticCase};

/// The lines that open a registration's run or server: its method, its organ (mesh, surface,
/// number of targets), `space` (what is done with the coordinates given), then the set-up's
/// warnings.
pub fn setup_lines(registration: &Registration, space: &str) -> Vec<String> {
    let organ = registration.organ();
    let mut lines = vec![
        format!("method     {}", registration.method()),
        format!(
            "organ      {} nodes, {} {} cells; surface of {} triangles{}; {} targets",
            organ.mesh().num_nodes(),
            organ.mesh().cells.len(),
            organ.mesh().cells.kind_name(),
            organ.surface().triangles.len(),
            match registration.own_surface() {
                Some(own) => format!(" (given back as its own, of {} triangles)", own.triangles.len()),
                None => String::new(),
            },
            registration.targets().len()
        ),
        format!("space      {space}"),
    ];
    lines.extend(registration.warnings().iter().map(|w| format!("warning    {w}")));
    lines
}

/// The rigid alignment's lines, with its error against `truth` (the true organ → cloud
/// transform) when known.
pub fn rigid_lines(r: &RigidResult, truth: Option<&RigidTransform>) -> Vec<String> {
    let t = r.organ_to_cloud();
    let mut lines = vec![format!(
        "rigid      ICP: organ -> cloud rotation {:.2} deg, translation {:.2} mm; {} iterations{}, {} of {} \
         points kept, rms {:.2} mm, {:.1} ms",
        t.angle().to_degrees(),
        mm(t.translation_norm()),
        r.iterations,
        if r.converged { "" } else { " (not converged)" },
        r.kept,
        r.points,
        mm(r.rms),
        ms(r.time)
    )];
    if let Some(truth) = truth {
        let (angle, shift) = t.error_to(truth);
        lines.push(format!(
            "           against the case's true misalignment ({:.2} deg, {:.2} mm): {:.2} deg, {:.2} mm off",
            truth.angle().to_degrees(),
            mm(truth.translation_norm()),
            angle.to_degrees(),
            mm(shift)
        ));
    }
    lines
}

/// Frame `i`'s line: points, iterations, residual, time and the TRE when known.
pub fn frame_line(i: usize, row: &FrameSummary) -> String {
    format!(
        "frame {i:<4} {} points ({} matched), {} iterations, surface residual {:.2} mm, {:.1} ms{}",
        row.points,
        row.inliers,
        row.iterations,
        row.surface_residual_mm,
        row.time_ms,
        row.tre_mean_mm
            .map_or(String::new(), |t| format!(", TRE mean {t:.2} mm, max {:.2} mm", row.tre_max_mm.unwrap_or(0.0)))
    )
}

/// The run's closing figures: the σ predicted at the targets (last frame; targets.csv has it in
/// `unit`) and the TRE when known.
pub fn run_lines(outcomes: &[FrameOutcome], summary: &Summary, unit: LengthUnit) -> Vec<String> {
    let mut lines = Vec::new();
    if let Some(sigma) = outcomes.last().and_then(|o| o.target_std.as_ref()) {
        lines.push(format!(
            "sigma      predicted at the targets: mean {:.2} mm, max {:.2} mm (targets.csv, column sigma_{})",
            mm(mesh::stats::mean(sigma)),
            mm(mesh::stats::max(sigma)),
            unit.symbol()
        ));
    }
    if let (Some(t), Some(m), Some(r)) = (summary.tre_mean_mm, summary.tre_max_mm, summary.no_deformation_tre_mean_mm) {
        lines.push(format!("TRE        mean {t:.2} mm, max {m:.2} mm (without deformation: mean {r:.2} mm)"));
    }
    lines
}

/// A comparison case in words: its truth, its camera and its misalignment.
pub fn case_lines(scenario: &CaseScenario) -> Vec<String> {
    let (t, c, m) = (&scenario.truth, &scenario.camera, &scenario.misalignment);
    let mut lines = vec![
        format!("case       {}: {}", scenario.name, scenario.description),
        format!(
            "truth      {} phantom (E = {} kPa, nu = {}) of {}, fixed on `{}`, {} N along {:?} on `{}`",
            t.material.law.display_name(),
            kpa(t.material.young),
            t.material.poisson,
            t.mesh_words(),
            t.fixed,
            t.force,
            t.direction,
            t.load
        ),
        format!(
            "camera     along {:?}: {} points on the visible surface, {} mm noise, {} % outliers (seed {})",
            c.view,
            c.points,
            mm(c.noise),
            c.outliers * 1e2,
            c.seed
        ),
    ];
    if m.rotation_deg != 0.0 || m.translation.in_metres() != 0.0 {
        lines.push(format!(
            "misaligned camera frame: {} deg about {:?}, then {} along {:?}",
            m.rotation_deg, m.axis, m.translation, m.direction
        ));
    }
    lines
}

/// The simulated case's frames and where they were written (`dir`).
pub fn case_files_lines(case: &SyntheticCase, dir: &Path) -> Vec<String> {
    if case.frames.len() > 1 {
        let forces: Vec<String> = case.frames.iter().map(|f| format!("{:.2}", f.force)).collect();
        vec![
            format!(
                "frames     {}: forces {} N, each frame warm-started from the previous one",
                forces.len(),
                forces.join(" ")
            ),
            format!(
                "case       {} (cloud.csv, truth.csv: the peak frame; clouds/, truths/: every frame; \
                 targets_rest.csv)",
                dir.display()
            ),
        ]
    } else {
        vec![format!("case       {} (cloud.csv, targets_rest.csv, truth.csv)", dir.display())]
    }
}

/// The comparison's table: a blank line, the header, then the baseline and each method (its
/// figures, or why it failed); the name column fits the longest method name.
pub fn comparison_table(rows: &[Compared]) -> Vec<String> {
    let width = rows.iter().map(|r| r.method.chars().count()).max().unwrap_or(0).max(28);
    let [t, m, res, time, p95, it] = COMPARISON_COLUMNS.map(|(_, label)| label);
    let mut lines =
        vec![String::new(), format!("{:<width$} {t:>14} {m:>13} {res:>14} {time:>10} {p95:>10} {it:>10}", "method")];
    for (name, values, error) in comparison_rows(rows) {
        let [t, m, res, time, p95, it] = values.map(|v| v.map_or("-".to_string(), |v| format!("{v:.2}")));
        lines.push(if error.is_empty() {
            format!("{name:<width$} {t:>14} {m:>13} {res:>14} {time:>10} {p95:>10} {it:>10}")
        } else {
            format!("{name:<width$} failed: {error}")
        });
    }
    lines
}

/// The figures of a row of [`comparison_rows`], in order: each one's CSV column and its label in
/// the printed table.
pub const COMPARISON_COLUMNS: [(&str, &str); 6] = [
    ("tre_mean_mm", "TRE mean (mm)"),
    ("tre_max_mm", "TRE max (mm)"),
    ("surface_residual_mm", "residual (mm)"),
    ("time_median_ms", "ms/frame"),
    ("time_p95_ms", "p95 (ms)"),
    ("iterations", "iterations"),
];

/// The rows of a comparison: the baseline (not deforming, or the rigid alignment alone, when the
/// methods aligned rigidly), then each method; each row its name, its figures (TRE mean and max,
/// surface residual in mm, median and 95th-percentile frame time in ms, iterations) and its error
/// (empty when it registered).
pub fn comparison_rows(rows: &[Compared]) -> Vec<(String, [Option<f64>; 6], String)> {
    let mut out = Vec::new();
    if let Some(first) = rows.iter().find_map(|r| r.result.as_ref().ok()) {
        let s = &first.summary;
        let name = if first.outcomes[0].rigid.is_some() { "rigid only (ICP)" } else { "no deformation" };
        out.push((
            name.to_string(),
            [s.no_deformation_tre_mean_mm, s.no_deformation_tre_max_mm, None, None, None, None],
            String::new(),
        ));
    }
    for r in rows {
        out.push(match &r.result {
            Ok(reg) => {
                let s = &reg.summary;
                let values = [
                    s.tre_mean_mm,
                    s.tre_max_mm,
                    Some(s.surface_residual_mm),
                    Some(s.time_median_ms),
                    Some(s.time_p95_ms),
                    Some(s.iterations),
                ];
                (r.method.clone(), values, String::new())
            }
            Err(e) => (r.method.clone(), [None; 6], e.to_string()),
        });
    }
    out
}
