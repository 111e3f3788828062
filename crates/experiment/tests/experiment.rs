//! The smallest experiment end to end (what `augsim experiment springs --size quick` runs),
//! its resumption and its report.

use augsim_experiment::{self as experiment, Name, Size};

#[test]
fn springs_experiment_writes_a_result_resumes_and_reports() {
    let root = tempfile::tempdir().unwrap();
    let result = experiment::run(Name::Springs, Size::Quick, root.path(), &learn::Silent).unwrap();
    let value = |row: usize| -> f64 { result.rows[row].ours.trim_end_matches(" mm").parse().unwrap() };
    let (estimated, fixed, free) = (value(0), value(1), value(2));
    println!("assessment errors: estimated {estimated} mm, fixed {fixed} mm, free {free} mm");
    // The published claim: estimated springs beat both fully fixed and free attachments.
    assert!(estimated < fixed && estimated < free, "{:?}", result.rows);
    for figure in &result.figures {
        assert!(root.path().join("springs").join(figure).exists(), "{figure} missing");
    }
    let lines = result.lines();
    assert_eq!(lines.len(), result.rows.len() + 1);
    assert!(lines[0].starts_with(result.name.title()) && lines[1].starts_with(&result.rows[0].label()), "{lines:?}");
    // It names the build that made it, and a second run of that build finds it and does not run again.
    assert_eq!(result.build, experiment::BUILD);
    assert!(
        result.notes.iter().any(|n| n.ends_with(&format!("by augsim {}.", experiment::VERSION))),
        "{:?}",
        result.notes
    );
    let again = experiment::run(Name::Springs, Size::Quick, root.path(), &learn::Silent).unwrap();
    assert_eq!(again, result);
    // A paper run would replace it: refused, the result kept.
    let e = experiment::run(Name::Springs, Size::Paper, root.path(), &learn::Silent).unwrap_err().to_string();
    assert!(e.contains("holds its quick result, which a paper run would replace"), "{e}");
    assert_eq!(experiment::load(&root.path().join("springs")).unwrap().as_ref(), Some(&result));
    let all = experiment::load_all(root.path()).unwrap();
    assert_eq!(all, vec![result.clone()]);
    let [md, html] = experiment::report::write(root.path(), &all).unwrap();
    let md = std::fs::read_to_string(md).unwrap();
    let html = std::fs::read_to_string(html).unwrap();
    assert!(md.contains(result.name.title()) && md.contains("| quantity | augsim | published |"));
    assert!(md.contains("![run/springs.png](springs/run/springs.png)"));
    assert!(html.contains("<img src=\"springs/run/springs.png\"") && !html.contains("http"));
}

#[test]
fn names_parse_and_unknown_ones_are_refused() {
    // The order `all` runs them in and the report follows.
    let names = Name::ALL.map(Name::as_str);
    assert_eq!(
        names,
        [
            "fem-speed",
            "fem-convergence",
            "fem-peer",
            "young",
            "springs",
            "liver-forces",
            "liver-ar",
            "beam-transfer",
            "beam-sparse",
            "stream",
            "held-out"
        ]
    );
    for name in Name::ALL {
        assert_eq!(Name::parse(name.as_str()).unwrap(), name);
    }
    let e = Name::parse("liver").unwrap_err().to_string();
    assert!(e.contains("unknown experiment 'liver'") && e.contains("beam-sparse"), "{e}");
    assert_eq!(Name::chosen("all").unwrap(), Name::ALL);
    assert_eq!(Name::chosen("stream").unwrap(), [Name::Stream]);
    assert!(Name::chosen("liver").is_err());
    for size in [experiment::Size::Quick, experiment::Size::Paper] {
        assert_eq!(size.as_str().parse::<experiment::Size>(), Ok(size));
    }
    assert_eq!("large".parse::<experiment::Size>(), Err("must be quick or paper, got 'large'".to_string()));
    let empty = tempfile::tempdir().unwrap();
    assert!(experiment::load_all(empty.path()).unwrap_err().to_string().contains("no experiment result"));
}

#[test]
fn the_readme_summary_and_the_results_page_come_from_the_same_results() {
    use experiment::{report, ExperimentResult, Headline, Row, Verdict};
    let dir = tempfile::tempdir().unwrap();
    let readme = dir.path().join("README.md");
    let [begin, end] = report::MARKERS;
    std::fs::write(&readme, format!("# title\n\nbefore\n{begin}\nold text\n{end}\nafter\n")).unwrap();
    let result = ExperimentResult {
        name: Name::Young,
        size: Size::Quick,
        seconds: 12.0,
        build: experiment::BUILD.into(),
        headlines: vec![
            Headline::lower_is_better("E error", 0.10, 0.16, 2, "%"),
            Headline::lower_is_better("filter time", 510.0, 500.0, 0, "s"),
            Headline::lower_is_better("TRE", 4.0, 3.0, 1, "mm"),
            Headline::finding("springs", "0.4 mm (fixed 0.9 mm)", "lower than fixed", true),
        ],
        rows: vec![Row::new("E", "4,990 ± 20 Pa", "4,992 ± 15 Pa")],
        figures: vec!["run/young.png".into()],
        page_figures: Vec::new(),
        notes: vec!["synthetic".into()],
        values: Default::default(),
    };
    let verdicts: Vec<Verdict> = result.headlines.iter().map(|h| h.verdict).collect();
    assert_eq!(verdicts, [Verdict::Better, Verdict::OnPar, Verdict::Worse, Verdict::OnPar]);
    assert_eq!(Headline::lower_is_better("x", f64::NAN, 1.0, 1, "mm").verdict, Verdict::Worse);
    let aim = |ours: f64| Headline::aim_lower("TRE a / b", "", "a as accurate as b", ours, 5.0).verdict;
    assert_eq!(
        [aim(3.6), aim(5.1), aim(6.2)],
        [Verdict::Better, Verdict::OnPar, Verdict::Worse],
        "an aim beaten is better"
    );
    report::update_markdown(&readme, std::slice::from_ref(&result)).unwrap();
    let text = std::fs::read_to_string(&readme).unwrap();
    assert!(text.starts_with("# title\n\nbefore\n") && text.ends_with(&format!("{end}\nafter\n")));
    assert!(!text.contains("old text") && text.contains("| E error | 0.10 % | 0.16 % | better |"), "{text}");
    assert!(!text.contains("4,990 ± 20 Pa"), "the README has the summary only");
    let page = dir.path().join("docs/results.md");
    report::write_results_page(&page, std::slice::from_ref(&result), dir.path()).unwrap();
    let page = std::fs::read_to_string(&page).unwrap();
    let summary = report::summary(std::slice::from_ref(&result));
    assert!(text.contains(summary.trim()) && page.contains(&summary), "one summary in both");
    let (at_summary, at_details) = (page.find("## Summary").unwrap(), page.find("### ROUKF: Young's modulus").unwrap());
    assert!(at_summary < at_details && page.contains("| E | 4,990 ± 20 Pa | 4,992 ± 15 Pa |"), "{page}");
    assert!(!page.contains("young.png"), "no figure links outside the run's directory");
    // A page figure is copied beside the page and shown there.
    let figure = dir.path().join("young/run/young.png");
    std::fs::create_dir_all(figure.parent().unwrap()).unwrap();
    std::fs::write(&figure, b"png").unwrap();
    let shown = ExperimentResult { page_figures: vec!["run/young.png".into()], ..result.clone() };
    let page = dir.path().join("docs/results.md");
    report::write_results_page(&page, std::slice::from_ref(&shown), dir.path()).unwrap();
    assert!(std::fs::read_to_string(&page).unwrap().contains("](young-young.png)"));
    assert_eq!(std::fs::read(dir.path().join("docs/young-young.png")).unwrap(), b"png");
    // A README whose summary shows another experiment, or this one at paper size, is not rewritten
    // from results that lack it: it keeps what it published.
    let shown = std::fs::read_to_string(&readme).unwrap();
    let more = shown.replace("(young quick)", "(young quick, stream paper)");
    std::fs::write(&readme, &more).unwrap();
    let e = report::update_markdown(&readme, std::slice::from_ref(&result)).unwrap_err().to_string();
    assert!(e.contains("shows results that --out does not hold at their size (stream paper)"), "{e}");
    assert_eq!(std::fs::read_to_string(&readme).unwrap(), more, "left as it was");
    std::fs::write(&readme, shown.replace("(young quick)", "(young paper)")).unwrap();
    let e = report::update_markdown(&readme, std::slice::from_ref(&result)).unwrap_err().to_string();
    assert!(e.contains("(young paper)"), "{e}");
    let paper = ExperimentResult { size: Size::Paper, ..result.clone() };
    std::fs::write(&readme, &shown).unwrap();
    report::update_markdown(&readme, std::slice::from_ref(&paper)).unwrap();
    // A marker named in the text as well as placed, a README that is the results page, a page
    // augsim did not write: refused before anything runs.
    std::fs::write(&readme, format!("keep `{begin}` once\n{shown}")).unwrap();
    let e = report::check_publish_paths(Some(&readme), None).unwrap_err().to_string();
    assert!(e.contains("more than once (one in its text?)"), "{e}");
    std::fs::write(&readme, &shown).unwrap();
    let e = report::check_publish_paths(Some(&readme), Some(&readme)).unwrap_err().to_string();
    assert!(e.contains("--readme and --results name one file"), "{e}");
    let e = report::check_publish_paths(None, Some(&readme)).unwrap_err().to_string();
    assert!(e.contains("is not a results page augsim wrote"), "{e}");
    assert!(report::check_publish_paths(Some(&readme), Some(&page)).is_ok());
    // Through a symbolic link, the file it names is rewritten, the link kept.
    #[cfg(unix)]
    {
        let link = dir.path().join("LINK.md");
        std::os::unix::fs::symlink(&readme, &link).unwrap();
        report::update_markdown(&link, std::slice::from_ref(&result)).unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    }
    std::fs::write(&readme, "no markers").unwrap();
    assert!(report::update_markdown(&readme, &[]).unwrap_err().to_string().contains("markers"));
}
