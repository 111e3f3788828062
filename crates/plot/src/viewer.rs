//! A self-contained HTML 3D viewer of a deformed surface: one file that opens in any browser without a network
//! connection (the data is embedded as JSON, the script is inline, Canvas 2D only).
//!
//! A [`Scene`] is a triangle surface at rest, the same surface in other positions (e.g. a reference and a
//! predicted deformation), an optional scalar per vertex shown as colour (e.g. the prediction error) and sets of
//! points (e.g. registration targets). The page draws the surface with flat Lambert shading, triangles sorted
//! back to front (painter's algorithm; back faces are culled when the surface is closed and consistently
//! oriented). Drag rotates, shift-drag pans, the wheel zooms, a double-click (or `r`) resets the view; buttons or
//! the keys `1`, `2`, ... switch between the rest shape and the layers, a slider scales the displacement,
//! checkboxes toggle the colour, the point sets, a translucent surface and the triangle edges. The colour bar gives
//! the scalar's range and unit.
//!
//! The page reports its own state for automated checks: `data-rendered="yes"` on `<body>` once a frame is drawn,
//! and a document title starting with `VIEWER ERROR` on any script error. Opened with `#bench` in the address it
//! draws every shape and option once, then times 60 frames of rotation and stores the mean time per frame (ms) in
//! `data-frame-ms` on `<body>`.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// A surface seen at rest and in other positions, with an optional colour and point sets.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scene {
    /// Title of the page.
    pub title: String,
    /// Lines shown under the title (e.g. what the sample is, error statistics).
    pub notes: Vec<String>,
    /// Triangles as indices into the vertex positions, counter-clockwise seen from outside when the surface is
    /// closed. Vertices no triangle uses are left out of the page.
    pub triangles: Vec<[u32; 3]>,
    /// Vertex positions at rest.
    pub rest: Vec<[f64; 3]>,
    /// The same vertices in other positions (one entry per vertex, same order as `rest`); the page opens on the
    /// last one.
    pub layers: Vec<Layer>,
    /// A scalar per vertex, shown as colour.
    pub colour: Option<Scalar>,
    /// Point sets drawn over the surface (visible through it).
    pub points: Vec<PointLayer>,
}

/// The surface's vertices in one position.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Layer {
    /// Button label (e.g. "reference", "prediction").
    pub name: String,
    /// Position of every vertex, in the order of [`Scene::rest`].
    pub positions: Vec<[f64; 3]>,
}

/// A scalar field on the vertices.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scalar {
    /// What it is (e.g. "prediction error").
    pub name: String,
    /// Its unit (e.g. "mm"); may be empty.
    pub unit: String,
    /// One finite value per vertex, in the order of [`Scene::rest`].
    pub values: Vec<f64>,
}

/// A set of points of one colour, drawn as outlined markers, or as small dots when it holds more
/// than 200 points (a cloud).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointLayer {
    /// Checkbox label.
    pub name: String,
    /// Positions.
    pub positions: Vec<[f64; 3]>,
    /// Colour (red, green, blue).
    pub colour: [u8; 3],
}

/// Errors of [`write_html`].
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The scene is inconsistent (index out of range, wrong length, non-finite value, nothing to draw).
    #[error("invalid scene: {0}")]
    Invalid(String),
    /// Writing the file failed.
    #[error("cannot write {path}: {error}")]
    Io {
        /// The target file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
}

impl Scene {
    /// Checks indices, lengths and finiteness; the error says which item is wrong.
    pub fn validate(&self) -> Result<(), ViewerError> {
        let bad = |m: String| Err(ViewerError::Invalid(m));
        let n = self.rest.len();
        if self.triangles.is_empty() {
            return bad("no triangle to draw".into());
        }
        if let Some((t, tri)) = self.triangles.iter().enumerate().find(|(_, t)| t.iter().any(|&i| i as usize >= n)) {
            return bad(format!("triangle {t} {tri:?} refers to a vertex beyond the {n} rest positions"));
        }
        let finite = |p: &[f64; 3]| p.iter().all(|x| x.is_finite());
        if let Some(v) = self.rest.iter().position(|p| !finite(p)) {
            return bad(format!("rest position of vertex {v} is not finite"));
        }
        for layer in &self.layers {
            if layer.positions.len() != n {
                return bad(format!("layer {:?} has {} positions for {n} vertices", layer.name, layer.positions.len()));
            }
            if let Some(v) = layer.positions.iter().position(|p| !finite(p)) {
                return bad(format!("layer {:?}: position of vertex {v} is not finite", layer.name));
            }
        }
        if let Some(c) = &self.colour {
            if c.values.len() != n {
                return bad(format!("colour {:?} has {} values for {n} vertices", c.name, c.values.len()));
            }
            if let Some(v) = c.values.iter().position(|x| !x.is_finite()) {
                return bad(format!("colour {:?}: value of vertex {v} is not finite", c.name));
            }
        }
        for set in &self.points {
            if let Some(p) = set.positions.iter().position(|p| !finite(p)) {
                return bad(format!("point set {:?}: point {p} is not finite", set.name));
            }
        }
        Ok(())
    }

    /// The page for this scene (see the module documentation).
    pub fn to_html(&self) -> Result<String, ViewerError> {
        self.validate()?;
        let title = if self.title.is_empty() { "augsim viewer" } else { self.title.as_str() };
        // The data first: its placeholder follows `<title>`, so a title holding a placeholder's name changes nothing.
        Ok(PAGE.replacen("__DATA__", &self.data_json(title), 1).replacen("__TITLE__", &escape_html(title), 1))
    }

    /// The scene as JSON (vertices no triangle uses left out, coordinates as f32), safe inside a `<script>`.
    fn data_json(&self, title: &str) -> String {
        // Keep only the vertices the triangles use, renumbered in order of first use.
        let mut new_index = vec![u32::MAX; self.rest.len()];
        let mut used = Vec::new();
        let mut triangles = Vec::with_capacity(3 * self.triangles.len());
        for &i in self.triangles.iter().flatten() {
            let slot = &mut new_index[i as usize];
            if *slot == u32::MAX {
                *slot = used.len() as u32;
                used.push(i as usize);
            }
            triangles.push(*slot);
        }
        let positions = |p: &[[f64; 3]]| used.iter().flat_map(|&v| p[v]).collect::<Vec<f64>>();
        let mut s = String::with_capacity(64 * used.len() * (2 + self.layers.len()));
        s.push_str("{\"title\":");
        push_string(&mut s, title);
        s.push_str(",\"notes\":[");
        for (k, note) in self.notes.iter().enumerate() {
            if k > 0 {
                s.push(',');
            }
            push_string(&mut s, note);
        }
        s.push_str("],\"triangles\":[");
        push_list(&mut s, triangles.iter().map(|i| i.to_string()));
        s.push_str("],\"rest\":");
        push_numbers(&mut s, &positions(&self.rest));
        s.push_str(",\"layers\":[");
        for (k, layer) in self.layers.iter().enumerate() {
            if k > 0 {
                s.push(',');
            }
            s.push_str("{\"name\":");
            push_string(&mut s, &layer.name);
            s.push_str(",\"positions\":");
            push_numbers(&mut s, &positions(&layer.positions));
            s.push('}');
        }
        s.push_str("],\"colour\":");
        match &self.colour {
            None => s.push_str("null"),
            Some(c) => {
                s.push_str("{\"name\":");
                push_string(&mut s, &c.name);
                s.push_str(",\"unit\":");
                push_string(&mut s, &c.unit);
                s.push_str(",\"values\":");
                push_numbers(&mut s, &used.iter().map(|&v| c.values[v]).collect::<Vec<_>>());
                s.push('}');
            }
        }
        s.push_str(",\"points\":[");
        for (k, set) in self.points.iter().enumerate() {
            if k > 0 {
                s.push(',');
            }
            s.push_str("{\"name\":");
            push_string(&mut s, &set.name);
            s.push_str(",\"positions\":");
            push_numbers(&mut s, &set.positions.iter().flatten().copied().collect::<Vec<_>>());
            let [r, g, b] = set.colour;
            let _ = write!(s, ",\"colour\":\"#{r:02x}{g:02x}{b:02x}\"}}");
        }
        s.push_str("]}");
        s
    }
}

/// Writes the viewer page of `scene` to `path` atomically (a temporary file in the same directory, renamed onto
/// `path` when complete). Fails on an inconsistent scene (see [`Scene::validate`]) without touching `path`.
pub fn write_html(path: &Path, scene: &Scene) -> Result<(), ViewerError> {
    let page = scene.to_html()?;
    let io = |error: std::io::Error| ViewerError::Io { path: path.to_path_buf(), error };
    let mut file = crate::sibling_tempfile(path, ".tmp").map_err(io)?;
    file.write_all(page.as_bytes()).map_err(io)?;
    file.as_file().sync_all().map_err(io)?;
    file.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// Appends comma-separated items.
fn push_list(s: &mut String, items: impl Iterator<Item = String>) {
    for (k, item) in items.enumerate() {
        if k > 0 {
            s.push(',');
        }
        s.push_str(&item);
    }
}

/// Appends a JSON array of numbers at f32 precision (shortest representation that reads back the same f32).
fn push_numbers(s: &mut String, values: &[f64]) {
    s.push('[');
    push_list(s, values.iter().map(|&v| (v as f32).to_string()));
    s.push(']');
}

/// Appends a JSON string; `<`, `>` and `&` are escaped too, so that no text can close the `<script>` element.
fn push_string(s: &mut String, text: &str) {
    s.push('"');
    for c in text.chars() {
        match c {
            '"' => s.push_str("\\\""),
            '\\' => s.push_str("\\\\"),
            '\n' => s.push_str("\\n"),
            '<' | '>' | '&' | '\u{2028}' | '\u{2029}' => {
                let _ = write!(s, "\\u{:04x}", u32::from(c));
            }
            c if u32::from(c) < 0x20 => {
                let _ = write!(s, "\\u{:04x}", u32::from(c));
            }
            c => s.push(c),
        }
    }
    s.push('"');
}

/// Text escaped for HTML content.
pub fn escape_html(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// The page: `__TITLE__` and `__DATA__` are replaced by the escaped title and the scene's JSON.
const PAGE: &str = r##"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>__TITLE__</title>
<script>
window.onerror = function (message, source, line) {
  document.title = "VIEWER ERROR: " + message + " (line " + line + ")";
  var box = document.getElementById("error");
  if (box) { box.textContent = document.title; box.hidden = false; }
};
window.addEventListener("unhandledrejection", function (e) { window.onerror(String(e.reason), "", 0); });
</script>
<style>
html, body { margin: 0; height: 100%; overflow: hidden; background: #f4f5f7; color: #1f2328;
  font: 13px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", Helvetica, Arial, sans-serif; }
canvas { position: absolute; left: 0; top: 0; cursor: grab; touch-action: none; }
canvas.dragging { cursor: grabbing; }
.box { position: absolute; background: rgba(255, 255, 255, 0.9); border: 1px solid #d0d5dc; border-radius: 6px;
  box-shadow: 0 1px 3px rgba(0, 0, 0, 0.08); }
#panel { left: 12px; top: 12px; max-width: min(440px, 55vw); padding: 10px 12px; }
#panel h1 { font-size: 15px; margin: 0 0 2px; }
#notes { color: #444; }
.row { margin-top: 8px; display: flex; flex-wrap: wrap; gap: 4px 10px; align-items: center; }
button { font: inherit; padding: 2px 10px; border: 1px solid #9aa3ad; border-radius: 4px; background: #fff;
  color: inherit; cursor: pointer; }
button.on { background: #2b6cb0; border-color: #2b6cb0; color: #fff; }
label { white-space: nowrap; cursor: pointer; }
input[type=range] { width: 110px; vertical-align: middle; }
.swatch { display: inline-block; width: 10px; height: 10px; border-radius: 50%; margin: 0 4px 0 2px;
  vertical-align: -1px; border: 1px solid rgba(0, 0, 0, 0.45); }
#bar { right: 14px; top: 50%; transform: translateY(-50%); padding: 10px 12px; display: flex; gap: 8px; }
#barname { writing-mode: vertical-rl; transform: rotate(180deg); text-align: center; font-weight: 600; }
#ramp { width: 20px; height: 280px; border: 1px solid #6b7280; }
#ticks { display: flex; flex-direction: column; justify-content: space-between; font-variant-numeric: tabular-nums;
  margin: -0.7em 0; }
#help { left: 12px; bottom: 10px; padding: 3px 8px; color: #555; font-size: 12px; }
#error { left: 50%; top: 12px; transform: translateX(-50%); padding: 8px 12px; background: #fde8e8;
  border-color: #e02424; color: #9b1c1c; }
[hidden] { display: none !important; }
</style>
</head>
<body>
<canvas id="view"></canvas>
<div id="panel" class="box">
  <h1 id="title"></h1>
  <div id="notes"></div>
  <div class="row" id="shapes"></div>
  <div class="row" id="options"></div>
</div>
<div id="bar" class="box" hidden><div id="barname"></div><div id="ramp"></div><div id="ticks"></div></div>
<div id="help" class="box">drag: rotate &middot; shift-drag: pan &middot; wheel: zoom &middot;
  double-click or r: reset view &middot; keys 1&ndash;9: shapes</div>
<div id="error" class="box" hidden></div>
<script id="scene" type="application/json">__DATA__</script>
<script>
"use strict";
(function () {
  const S = JSON.parse(document.getElementById("scene").textContent);
  const tri = S.triangles, nt = tri.length / 3, nv = S.rest.length / 3;
  const shapes = [{ name: "rest", positions: S.rest }].concat(S.layers);
  const BACKGROUND = "#f4f5f7", PLAIN = [205, 120, 95];
  const DOTS = 200; // a set of more points (a cloud) is drawn as small dots, not as markers
  const LIGHT = [-0.3, 0.4, 0.87].map((x, _, l) => x / Math.hypot(...l)); // view coordinates, towards the light
  // Sequential yellow-orange-red (ColorBrewer YlOrRd, 9 stops): light where the value is low, so that the shading
  // shows the shape.
  const MAP = [[255, 255, 204], [255, 237, 160], [254, 217, 118], [254, 178, 76], [253, 141, 60], [252, 78, 42],
    [227, 26, 28], [189, 0, 38], [128, 0, 38]];
  const state = { shape: shapes.length - 1, scale: 1, coloured: !!S.colour, translucent: false, edges: false,
    points: S.points.map(() => true) };

  // ---- geometry: centre and size of everything that can be shown
  let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  const grow = (a) => { for (let i = 0; i < a.length; i++) { const d = i % 3;
    if (a[i] < lo[d]) lo[d] = a[i]; if (a[i] > hi[d]) hi[d] = a[i]; } };
  shapes.forEach((s) => grow(s.positions)); S.points.forEach((p) => grow(p.positions));
  const centre = [0, 1, 2].map((d) => 0.5 * (lo[d] + hi[d]));
  const radius = Math.max(1e-12, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));

  // Back faces can be culled when every edge is shared by two triangles of opposite orientation; their
  // orientation (outward or inward) is the sign of the enclosed volume.
  const cull = (function () {
    const edges = new Set(), key = (a, b) => a * nv + b;
    for (let t = 0; t < nt; t++) for (let k = 0; k < 3; k++) {
      const e = key(tri[3 * t + k], tri[3 * t + (k + 1) % 3]);
      if (edges.has(e)) return 0;
      edges.add(e);
    }
    for (const e of edges) if (!edges.has((e % nv) * nv + Math.floor(e / nv))) return 0;
    const p = S.rest; let volume = 0;
    for (let t = 0; t < nt; t++) {
      const a = 3 * tri[3 * t], b = 3 * tri[3 * t + 1], c = 3 * tri[3 * t + 2];
      volume += p[a] * (p[b + 1] * p[c + 2] - p[b + 2] * p[c + 1]) - p[a + 1] * (p[b] * p[c + 2] - p[b + 2] * p[c])
        + p[a + 2] * (p[b] * p[c + 1] - p[b + 1] * p[c]);
    }
    return volume > 0 ? 1 : volume < 0 ? -1 : 0;
  })();

  // ---- colour
  const mapColour = (t) => {
    const x = Math.min(1, Math.max(0, t)) * (MAP.length - 1), i = Math.min(MAP.length - 2, Math.floor(x)), f = x - i;
    return [0, 1, 2].map((c) => MAP[i][c] + f * (MAP[i + 1][c] - MAP[i][c]));
  };
  let cmin = 0, cmax = 1;
  if (S.colour) {
    cmin = Infinity; cmax = -Infinity;
    for (const x of S.colour.values) { if (x < cmin) cmin = x; if (x > cmax) cmax = x; }
    if (!(cmax > cmin)) { cmax = cmin + (Math.abs(cmin) || 1); }
  }
  // The colour scale ends at the 99th percentile (values above it saturate), unless changed with the slider.
  let ctop = cmax;
  if (S.colour) {
    const sorted = Float64Array.from(S.colour.values).sort(), p99 = sorted[Math.floor(0.99 * (sorted.length - 1))];
    if (p99 > cmin) ctop = p99;
  }
  const triangleColour = new Float32Array(3 * nt);
  function paintTriangles() {
    for (let t = 0; t < nt; t++) {
      let rgb = PLAIN;
      if (state.coloured && S.colour) {
        const v = S.colour.values, mean = (v[tri[3 * t]] + v[tri[3 * t + 1]] + v[tri[3 * t + 2]]) / 3;
        rgb = mapColour((mean - cmin) / (ctop - cmin));
      }
      triangleColour.set(rgb, 3 * t);
    }
  }

  // ---- view: rotation R (row-major 3x3, world to view; view z towards the eye), zoom, pan (pixels)
  const INITIAL = (function () {
    const a = -0.75, b = 0.3, ca = Math.cos(a), sa = Math.sin(a), cb = Math.cos(b), sb = Math.sin(b);
    return mul([1, 0, 0, 0, ca, -sa, 0, sa, ca], [cb, 0, sb, 0, 1, 0, -sb, 0, cb]);
  })();
  let R = INITIAL.slice(), zoom = 1, pan = [0, 0];
  function mul(A, B) {
    const C = new Array(9);
    for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++)
      C[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
    return C;
  }
  function orthonormalise(M) {
    const r0 = M.slice(0, 3), r1 = M.slice(3, 6), n0 = Math.hypot(...r0);
    for (let k = 0; k < 3; k++) r0[k] /= n0;
    const d = r0[0] * r1[0] + r0[1] * r1[1] + r0[2] * r1[2];
    for (let k = 0; k < 3; k++) r1[k] -= d * r0[k];
    const n1 = Math.hypot(...r1);
    for (let k = 0; k < 3; k++) r1[k] /= n1;
    const r2 = [r0[1] * r1[2] - r0[2] * r1[1], r0[2] * r1[0] - r0[0] * r1[2], r0[0] * r1[1] - r0[1] * r1[0]];
    return r0.concat(r1, r2);
  }
  function rotate(ax, ay) {
    const cx = Math.cos(ax), sx = Math.sin(ax), cy = Math.cos(ay), sy = Math.sin(ay);
    R = orthonormalise(mul(mul([cy, 0, sy, 0, 1, 0, -sy, 0, cy], [1, 0, 0, 0, cx, -sx, 0, sx, cx]), R));
  }

  // ---- drawing
  const canvas = document.getElementById("view");
  // The benchmark reads a pixel back after each frame (so that the frame is rasterised): a CPU canvas for it.
  const ctx = canvas.getContext("2d", { willReadFrequently: location.hash === "#bench" });
  let width = 0, height = 0, middle = 0, room = 0;
  // The view is centred in the room left between the panel (when it leaves enough) and the colour bar.
  function layout() {
    const panel = document.getElementById("panel").getBoundingClientRect(), bar = document.getElementById("bar");
    const left = panel.right + 8 < 0.45 * width ? panel.right + 8 : 0;
    const right = bar.hidden ? width : bar.getBoundingClientRect().left - 8;
    middle = 0.5 * (left + right); room = Math.max(0.3 * width, right - left);
  }
  function resize() {
    const dpr = window.devicePixelRatio || 1;
    width = window.innerWidth; height = window.innerHeight;
    canvas.width = Math.round(width * dpr); canvas.height = Math.round(height * dpr);
    canvas.style.width = width + "px"; canvas.style.height = height + "px";
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    layout();
  }
  const sx = new Float32Array(nv), sy = new Float32Array(nv), sz = new Float32Array(nv);
  const depth = new Float32Array(nt), shade = new Float32Array(nt), order = new Uint32Array(nt);
  function project(x, y, z, s) {
    x -= centre[0]; y -= centre[1]; z -= centre[2];
    return [middle + pan[0] + s * (R[0] * x + R[1] * y + R[2] * z),
      height / 2 + pan[1] - s * (R[3] * x + R[4] * y + R[5] * z), R[6] * x + R[7] * y + R[8] * z];
  }
  function draw() {
    const s = zoom * 0.5 * Math.min(room, height) / radius;
    const P = shapes[state.shape].positions, Q = S.rest, k = state.shape === 0 ? 1 : state.scale;
    for (let v = 0; v < nv; v++) {
      const i = 3 * v;
      const p = project(Q[i] + k * (P[i] - Q[i]), Q[i + 1] + k * (P[i + 1] - Q[i + 1]), Q[i + 2] + k * (P[i + 2] - Q[i + 2]), s);
      sx[v] = p[0]; sy[v] = p[1]; sz[v] = p[2];
    }
    let m = 0;
    for (let t = 0; t < nt; t++) {
      const a = tri[3 * t], b = tri[3 * t + 1], c = tri[3 * t + 2];
      // Normal in view coordinates (screen y points down, hence the signs).
      const ux = sx[b] - sx[a], uy = sy[a] - sy[b], uz = (sz[b] - sz[a]) * s;
      const wx = sx[c] - sx[a], wy = sy[a] - sy[c], wz = (sz[c] - sz[a]) * s;
      const nx = uy * wz - uz * wy, ny = uz * wx - ux * wz, nz = ux * wy - uy * wx;
      if (cull !== 0 && !state.translucent && cull * nz <= 0) continue;
      // Two-sided Lambert shading: the normal turned towards the eye, a light above left of the eye.
      const n = (nz < 0 ? -1 : 1) * Math.hypot(nx, ny, nz);
      const lit = n !== 0 ? (LIGHT[0] * nx + LIGHT[1] * ny + LIGHT[2] * nz) / n : 0;
      shade[t] = 0.45 + 0.55 * Math.max(0, lit);
      depth[t] = sz[a] + sz[b] + sz[c];
      order[m++] = t;
    }
    const visible = order.subarray(0, m).sort((p, q) => depth[p] - depth[q]);
    ctx.globalAlpha = 1;
    ctx.fillStyle = BACKGROUND; ctx.fillRect(0, 0, width, height);
    ctx.lineJoin = "round";
    ctx.globalAlpha = state.translucent ? 0.35 : 1;
    ctx.lineWidth = state.edges ? 0.5 : 0.8;
    for (let j = 0; j < m; j++) {
      const t = visible[j], a = tri[3 * t], b = tri[3 * t + 1], c = tri[3 * t + 2], f = shade[t];
      const colour = "rgb(" + Math.round(f * triangleColour[3 * t]) + "," + Math.round(f * triangleColour[3 * t + 1])
        + "," + Math.round(f * triangleColour[3 * t + 2]) + ")";
      ctx.beginPath(); ctx.moveTo(sx[a], sy[a]); ctx.lineTo(sx[b], sy[b]); ctx.lineTo(sx[c], sy[c]); ctx.closePath();
      ctx.fillStyle = colour; ctx.fill();
      if (state.edges) { ctx.strokeStyle = "rgba(20,20,20,0.35)"; ctx.stroke(); }
      else if (!state.translucent) { ctx.strokeStyle = colour; ctx.stroke(); } // hides anti-aliasing seams
    }
    ctx.globalAlpha = 1;
    S.points.forEach((set, i) => {
      if (!state.points[i]) return;
      ctx.fillStyle = set.colour; ctx.strokeStyle = "rgba(0,0,0,0.75)"; ctx.lineWidth = 1;
      const p = set.positions, dots = p.length > 3 * DOTS, r = dots ? 1.8 : 4.5;
      for (let j = 0; j < p.length; j += 3) {
        const q = project(p[j], p[j + 1], p[j + 2], s);
        ctx.beginPath(); ctx.arc(q[0], q[1], r, 0, 2 * Math.PI); ctx.fill(); if (!dots) ctx.stroke();
      }
    });
    drawAxes();
  }
  function drawAxes() {
    const ox = width - 48, oy = height - 44, L = 26, names = ["x", "y", "z"], colours = ["#d62728", "#2ca02c", "#1f77b4"];
    ctx.lineWidth = 2; ctx.font = "12px sans-serif"; ctx.textAlign = "center"; ctx.textBaseline = "middle";
    [0, 1, 2].sort((p, q) => R[6 + p] - R[6 + q]).forEach((d) => {
      const ex = R[d], ey = -R[3 + d];
      ctx.strokeStyle = colours[d]; ctx.fillStyle = colours[d];
      ctx.beginPath(); ctx.moveTo(ox, oy); ctx.lineTo(ox + L * ex, oy + L * ey); ctx.stroke();
      ctx.fillText(names[d], ox + (L + 9) * ex, oy + (L + 9) * ey);
    });
  }
  let pending = false;
  function request() {
    if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; draw(); }); }
  }

  // ---- controls
  const el = (tag, attrs, text) => { const e = document.createElement(tag); Object.assign(e, attrs || {});
    if (text !== undefined) e.textContent = text; return e; };
  document.getElementById("title").textContent = S.title;
  S.notes.forEach((n) => document.getElementById("notes").appendChild(el("div", {}, n)));
  const shapeRow = document.getElementById("shapes"), buttons = [];
  const scaleLabel = el("label", {}, "displacement \u00d7 "), scaleValue = el("span", {}, "1");
  const scaleInput = el("input", { type: "range", min: "0", max: "5", step: "0.1", value: "1" });
  scaleLabel.appendChild(scaleInput); scaleLabel.appendChild(scaleValue);
  function selectShape(i) {
    state.shape = i;
    buttons.forEach((b, j) => b.classList.toggle("on", j === i));
    scaleLabel.hidden = i === 0;
    request();
  }
  shapes.forEach((shape, i) => {
    const b = el("button", { type: "button", title: "key " + (i + 1) }, shape.name);
    b.addEventListener("click", () => selectShape(i));
    buttons.push(b); shapeRow.appendChild(b);
  });
  shapeRow.appendChild(scaleLabel);
  scaleInput.addEventListener("input", () => {
    state.scale = parseFloat(scaleInput.value); scaleValue.textContent = scaleInput.value; request();
  });
  const options = document.getElementById("options");
  function checkbox(text, checked, change, swatch) {
    const label = el("label"), box = el("input", { type: "checkbox", checked: checked });
    box.addEventListener("change", () => { change(box.checked); request(); });
    label.appendChild(box);
    if (swatch) { const s = el("span", { className: "swatch" }); s.style.background = swatch; label.appendChild(s); }
    label.appendChild(document.createTextNode(text));
    options.appendChild(label);
  }
  if (S.colour) {
    checkbox("colour: " + S.colour.name, true, (on) => {
      state.coloured = on; paintTriangles(); document.getElementById("bar").hidden = !on; layout();
    });
    const label = el("label", {}, "colour max "), slider = el("input", { type: "range", min: "1", max: "1000" });
    slider.value = String(Math.round(1000 * (ctop - cmin) / (cmax - cmin)));
    slider.addEventListener("input", () => {
      ctop = cmin + (cmax - cmin) * parseInt(slider.value, 10) / 1000; paintTriangles(); ticks(); request();
    });
    label.appendChild(slider); options.appendChild(label);
  }
  S.points.forEach((set, i) => checkbox(set.name + " (" + set.positions.length / 3 + ")", true,
    (on) => { state.points[i] = on; }, set.colour));
  checkbox("translucent", false, (on) => { state.translucent = on; });
  checkbox("edges", false, (on) => { state.edges = on; });

  function format(x) {
    const a = Math.abs(x);
    if (a <= 1e-9 * (Math.abs(cmax) + Math.abs(cmin))) return "0";
    if (a >= 1e4 || a < 1e-3) return x.toExponential(2);
    return String(parseFloat(x.toPrecision(3)));
  }
  if (S.colour) {
    const bar = document.getElementById("bar");
    document.getElementById("barname").textContent = S.colour.name + (S.colour.unit ? " (" + S.colour.unit + ")" : "");
    document.getElementById("ramp").style.background = "linear-gradient(to top, " +
      MAP.map((c, i) => "rgb(" + c.join(",") + ") " + (100 * i / (MAP.length - 1)).toFixed(1) + "%").join(", ") + ")";
    ticks();
    bar.hidden = false;
  }
  function ticks() {
    const box = document.getElementById("ticks");
    box.replaceChildren();
    for (let i = 4; i >= 0; i--) {
      box.appendChild(el("div", {}, (i === 4 && ctop < cmax ? "\u2265 " : "") + format(cmin + (ctop - cmin) * i / 4)));
    }
  }

  // ---- interaction
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 1 || e.button === 2 };
    canvas.setPointerCapture(e.pointerId); canvas.classList.add("dragging");
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) { pan[0] += dx; pan[1] += dy; } else rotate(dy * 0.01, dx * 0.01);
    request();
  });
  const release = () => { drag = null; canvas.classList.remove("dragging"); };
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    zoom = Math.min(50, Math.max(0.05, zoom * Math.exp(-0.0015 * e.deltaY))); request();
  }, { passive: false });
  const reset = () => { R = INITIAL.slice(); zoom = 1; pan = [0, 0]; request(); };
  canvas.addEventListener("dblclick", reset);
  window.addEventListener("keydown", (e) => {
    if (e.target instanceof HTMLInputElement && e.target.type === "range") return;
    const i = parseInt(e.key, 10);
    if (i >= 1 && i <= shapes.length) selectShape(i - 1);
    else if (e.key === "r") reset();
  });
  window.addEventListener("resize", () => { resize(); request(); });

  resize(); paintTriangles(); selectShape(state.shape); draw();
  document.body.dataset.rendered = "yes";
  if (location.hash === "#bench") {
    // Every drawing path once (each shape; translucent, with edges, without colour), then timed rotation frames.
    shapes.forEach((_, i) => { selectShape(i); draw(); });
    Object.assign(state, { translucent: true, edges: true, coloured: false }); paintTriangles(); draw();
    Object.assign(state, { translucent: false, edges: false, coloured: !!S.colour }); paintTriangles();
    selectShape(shapes.length - 1);
    const frames = 60, t0 = performance.now();
    for (let f = 0; f < frames; f++) { rotate(0.004, 0.02); draw(); ctx.getImageData(0, 0, 1, 1); }
    document.body.dataset.frameMs = ((performance.now() - t0) / frames).toFixed(2);
    reset();
  }
})();
</script>
</body>
</html>
"##;
