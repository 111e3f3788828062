//! The HTML viewer: the page embeds the scene and nothing external, bad scenes are refused, and (ignored by
//! default, needs Chromium) the page runs in a headless browser without error and draws the surface.

use std::path::{Path, PathBuf};
use std::process::Command;

use augsim_plot::viewer::{write_html, Layer, PointLayer, Scalar, Scene, ViewerError};

/// A unit cube (8 corners, 12 outward triangles), one unused vertex, a sheared layer, a colour and two points.
fn cube() -> Scene {
    let mut rest: Vec<[f64; 3]> =
        (0..8).map(|i| [f64::from(i & 1), f64::from(i >> 1 & 1), f64::from(i >> 2 & 1)]).collect();
    rest.push([5.0, 5.0, 5.0]); // used by no triangle
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let triangles = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    let sheared = rest.iter().map(|p| [p[0] + 0.3 * p[2], p[1], p[2]]).collect();
    Scene {
        title: "cube </script> & <b>".into(),
        notes: vec!["a note".into()],
        triangles,
        rest: rest.clone(),
        layers: vec![Layer { name: "sheared".into(), positions: sheared }],
        colour: Some(Scalar { name: "height".into(), unit: "m".into(), values: rest.iter().map(|p| p[2]).collect() }),
        points: vec![PointLayer {
            name: "targets".into(),
            positions: vec![[0.5, 0.5, 0.5], [0.2, 0.8, 0.4]],
            colour: [255, 0, 0],
        }],
    }
}

/// A UV sphere of `n` × 2n quads (about 4n² triangles, outward) deformed into an egg, coloured by the
/// displacement, with points inside.
fn sphere(n: usize) -> Scene {
    let (rings, segments) = (n, 2 * n);
    let mut rest = vec![[0.0, 0.0, 1.0]];
    for i in 1..rings {
        let theta = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..segments {
            let phi = 2.0 * std::f64::consts::PI * j as f64 / segments as f64;
            rest.push([theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]);
        }
    }
    rest.push([0.0, 0.0, -1.0]);
    let south = (rest.len() - 1) as u32;
    let at = |i: usize, j: usize| (1 + (i - 1) * segments + j % segments) as u32;
    let mut triangles = Vec::new();
    for j in 0..segments {
        triangles.push([0, at(1, j), at(1, j + 1)]);
        triangles.push([south, at(rings - 1, j + 1), at(rings - 1, j)]);
        for i in 1..rings - 1 {
            triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    let egg: Vec<[f64; 3]> = rest.iter().map(|p| [p[0] * (1.0 + 0.25 * p[2]), p[1], 1.3 * p[2]]).collect();
    let moved = rest.iter().zip(&egg).map(|(a, b)| (0..3).map(|d| (a[d] - b[d]).powi(2)).sum::<f64>().sqrt()).collect();
    Scene {
        title: "egg".into(),
        notes: vec![format!("{} triangles", triangles.len())],
        triangles,
        layers: vec![Layer { name: "egg".into(), positions: egg }],
        colour: Some(Scalar { name: "displacement".into(), unit: "m".into(), values: moved }),
        points: vec![PointLayer {
            name: "inside".into(),
            positions: vec![[0.0, 0.0, 0.0], [0.3, 0.2, 0.1], [-0.2, 0.4, -0.3]],
            colour: [230, 60, 40],
        }],
        rest,
    }
}

/// The numbers of the JSON array that follows `key` in `page`.
fn array_after(page: &str, key: &str) -> Vec<f64> {
    let start = page.find(key).unwrap_or_else(|| panic!("{key} not in the page")) + key.len();
    let end = start + page[start..].find(']').unwrap();
    page[start..end].split(',').map(|x| x.parse().unwrap()).collect()
}

#[test]
fn page_embeds_the_scene_and_nothing_external() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cube.html");
    write_html(&path, &cube()).unwrap();
    let page = std::fs::read_to_string(&path).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"));
    for url in ["http://", "https://", "//cdn", "src=", "<link", "@import"] {
        assert!(!page.contains(url), "the page must not load anything ({url} found)");
    }
    // The title cannot close the script or inject markup.
    assert!(page.contains("<title>cube &lt;/script&gt; &amp; &lt;b&gt;</title>"));
    assert_eq!(page.matches("</script>").count(), 3, "only the page's own three scripts are closed");
    assert!(page.contains(r#""title":"cube \u003c/script\u003e \u0026 \u003cb\u003e""#));
    // The unused vertex is left out: 8 corners remain, at f32 precision; triangles refer to them.
    let rest = array_after(&page, r#""rest":["#);
    assert_eq!(rest.len(), 24);
    assert!(rest.iter().all(|&x| x == 0.0 || x == 1.0));
    let triangles = array_after(&page, r#""triangles":["#);
    assert_eq!(triangles.len(), 36);
    assert!(triangles.iter().all(|&i| (0.0..8.0).contains(&i)));
    assert_eq!(array_after(&page, r#""values":["#).len(), 8);
    for text in [r#""name":"sheared""#, r#""name":"height","unit":"m""#, r##""colour":"#ff0000""##, r#""a note""#] {
        assert!(page.contains(text), "{text} not in the page");
    }
    assert!(page.contains(r#""points":[{"name":"targets","positions":[0.5,0.5,0.5,0.2,0.8,0.4]"#));
    // No temporary file is left beside it.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    // A folder that does not exist yet is made.
    let nested = dir.path().join("out/views/cube.html");
    write_html(&nested, &cube()).unwrap();
    assert!(std::fs::read_to_string(&nested).unwrap().starts_with("<!DOCTYPE html>"));
}

#[test]
fn a_title_naming_the_placeholders_leaves_the_page_intact() {
    let scene = Scene { title: "a __DATA__ b __TITLE__".into(), ..cube() };
    let page = scene.to_html().unwrap();
    assert!(page.contains("<title>a __DATA__ b __TITLE__</title>"));
    let script = r#"<script id="scene" type="application/json">{"title":"a __DATA__ b __TITLE__","#;
    assert!(page.contains(script), "the scene's data is not in its script");
    assert!(!page.contains(">__DATA__<"));
    assert_eq!(page.matches("__DATA__").count(), 2, "the title's two copies only");
}

#[test]
fn bad_scenes_are_refused_without_writing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.html");
    let refuse = |scene: Scene, expected: &str| {
        match write_html(&path, &scene) {
            Err(ViewerError::Invalid(m)) => assert!(m.contains(expected), "{m:?} does not mention {expected:?}"),
            other => panic!("expected an invalid-scene error mentioning {expected:?}, got {other:?}"),
        }
        assert!(!path.exists());
    };
    let mut s = cube();
    s.triangles[3] = [0, 1, 9];
    refuse(s, "triangle 3");
    let mut s = cube();
    s.layers[0].positions.pop();
    refuse(s, "layer \"sheared\" has 8 positions for 9 vertices");
    let mut s = cube();
    s.colour.as_mut().unwrap().values[2] = f64::NAN;
    refuse(s, "value of vertex 2 is not finite");
    let mut s = cube();
    s.colour.as_mut().unwrap().values.push(0.0);
    refuse(s, "10 values for 9 vertices");
    let mut s = cube();
    s.rest[4][1] = f64::INFINITY;
    refuse(s, "rest position of vertex 4");
    let mut s = cube();
    s.points[0].positions[1][0] = f64::NAN;
    refuse(s, "point set \"targets\": point 1");
    let mut s = cube();
    s.triangles.clear();
    refuse(s, "no triangle");
    // A path under a file is an I/O error naming the file.
    std::fs::write(dir.path().join("plain"), "").unwrap();
    let e = write_html(&dir.path().join("plain/x.html"), &cube()).unwrap_err();
    assert!(matches!(e, ViewerError::Io { .. }) && e.to_string().contains("plain"), "{e}");
}

/// The Chromium binary: `$CHROMIUM`, or `chromium`, `chromium-browser` or `google-chrome` on the path.
fn chromium() -> PathBuf {
    if let Some(p) = std::env::var_os("CHROMIUM") {
        return PathBuf::from(p);
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    for name in ["chromium", "chromium-browser", "google-chrome", "google-chrome-stable"] {
        if let Some(found) = std::env::split_paths(&path).map(|d| d.join(name)).find(|p| p.is_file()) {
            return found;
        }
    }
    panic!("Chromium not found: install it (Debian: apt-get install chromium) or set CHROMIUM to its path");
}

/// Runs headless Chromium on `url` with `args` (after the common ones); returns (stdout, stderr), failing on a
/// non-zero exit.
fn run_chromium(profile: &Path, url: &str, args: &[&str]) -> (String, String) {
    let out = Command::new(chromium())
        .args(["--headless=new", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0"])
        .args(["--no-first-run", "--disable-extensions", "--window-size=900,700"])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .arg(url)
        .output()
        .expect("cannot run Chromium");
    let (stdout, stderr) =
        (String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned());
    assert!(out.status.success(), "Chromium failed ({}):\n{stderr}", out.status);
    (stdout, stderr)
}

/// The text of the `<title>` element of a dumped page.
fn title_of(dom: &str) -> &str {
    dom.split("<title>").nth(1).and_then(|s| s.split("</title>").next()).expect("no title")
}

/// Lets the page load and run its scripts before the DOM or the screenshot is taken.
const VIRTUAL_TIME: &str = "--virtual-time-budget=3000";

/// Console messages and uncaught errors in Chromium's log (the page itself logs nothing).
fn console_lines(stderr: &str) -> Vec<&str> {
    stderr.lines().filter(|l| l.contains("CONSOLE") || l.contains("Uncaught")).collect()
}

#[test]
#[ignore = "needs chromium: cargo test -p augsim-plot --test viewer -- --ignored"]
fn page_renders_in_headless_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let scene = sphere(34);
    assert!(scene.triangles.len() > 4000);
    let path = dir.path().join("egg.html");
    write_html(&path, &scene).unwrap();
    let url = format!("file://{}", path.display());
    let profile = dir.path().join("profile");

    // The script ran to the end, without error.
    let (dom, stderr) = run_chromium(&profile, &url, &[VIRTUAL_TIME, "--dump-dom"]);
    assert_eq!(console_lines(&stderr), Vec::<&str>::new(), "console output:\n{stderr}");
    assert_eq!(title_of(&dom), "egg", "the page reported an error (window.onerror writes it into the title)");
    assert!(dom.contains(r#"<body data-rendered="yes""#), "the page did not draw:\n{dom}");

    // The screenshot shows the surface: it covers most of the middle of the window, in colour.
    let png = dir.path().join("egg.png");
    let (_, stderr) = run_chromium(&profile, &url, &[VIRTUAL_TIME, &format!("--screenshot={}", png.display())]);
    assert_eq!(console_lines(&stderr), Vec::<&str>::new(), "console output:\n{stderr}");
    if let Some(keep) = std::env::var_os("VIEWER_SCREENSHOT") {
        std::fs::copy(&png, keep).unwrap(); // to look at it
    }
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&png).expect("no screenshot")));
    let mut reader = decoder.read_info().unwrap();
    let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut pixels).unwrap();
    let channels = info.color_type.samples();
    assert!(channels >= 3 && info.bit_depth == png::BitDepth::Eight, "{info:?}");
    let (w, h) = (info.width as usize, info.height as usize);
    assert_eq!((w, h), (900, 700));
    let pixel = |x: usize, y: usize| {
        let i = (y * w + x) * channels;
        [pixels[i], pixels[i + 1], pixels[i + 2]]
    };
    let background = pixel(w / 2, h - 3);
    assert_eq!(background, [0xf4, 0xf5, 0xf7], "background");
    let differs = |p: [u8; 3]| p.iter().zip(background).map(|(a, b)| a.abs_diff(b) as u32).sum::<u32>() > 40;
    let all = (0..h).flat_map(|y| (0..w).map(move |x| (x, y)));
    let changed = all.clone().filter(|&(x, y)| differs(pixel(x, y))).count() as f64 / (w * h) as f64;
    let middle = all.filter(|&(x, y)| (w / 3..2 * w / 3).contains(&x) && (h / 3..2 * h / 3).contains(&y));
    let (covered, total) = middle.fold((0, 0), |(c, t), (x, y)| (c + usize::from(differs(pixel(x, y))), t + 1));
    let covered = covered as f64 / total as f64;
    println!(
        "{:.1} % of the screenshot differ from the background, {:.1} % of its middle",
        100.0 * changed,
        100.0 * covered
    );
    assert!(changed > 0.15, "screenshot nearly blank: {:.1} % drawn", 100.0 * changed);
    assert!(covered > 0.6, "the surface does not cover the middle: {:.1} %", 100.0 * covered);
    let hues = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| pixel(x, y))
        .filter(|p| p.iter().max().unwrap() - p.iter().min().unwrap() > 60)
        .count();
    assert!(hues as f64 > 0.05 * (w * h) as f64, "too few coloured pixels: {hues}");

    // Every drawing path once without error, and the time of a rotation frame (software rendering, real time).
    let (dom, stderr) = run_chromium(&profile, &format!("{url}#bench"), &["--dump-dom"]);
    assert_eq!(console_lines(&stderr), Vec::<&str>::new(), "console output:\n{stderr}");
    assert_eq!(title_of(&dom), "egg", "the page reported an error (window.onerror writes it into the title)");
    let ms: f64 = dom
        .split("data-frame-ms=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .and_then(|s| s.parse().ok())
        .expect("no frame time in the page");
    println!("{} triangles: {ms:.2} ms per rotation frame", scene.triangles.len());
    assert!(ms.is_finite() && ms > 0.0);
}
