//! `augsim prepare`: a patient's organ from its segmented surface to a registration set-up
//! (see `augsim_app::prepare`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use app::prepare::{prepare, CameraAt, PrepareOptions, PrepareProgress, STEPS};

use crate::bar::Bar;

/// Arguments of `augsim prepare`.
#[derive(clap::Args)]
pub struct PrepareArgs {
    /// The segmented organ: a surface (.stl, .obj, .ply, .vtk, .vtp, .vtu) as a segmentation gives it (holes,
    /// duplicated vertices and flipped triangles are repaired; what local repair cannot mend is
    /// rebuilt through voxels), or a labelmap (.nii, .nii.gz from TotalSegmentator, .seg.nrrd
    /// from 3D Slicer, .nrrd, .nhdr, .mha, .mhd; in mm, in the scanner's frame the file states, RAS or LPS).
    surface: PathBuf,
    /// The labelmap's label: a number (TotalSegmentator's liver is 5) or a segment name (3D
    /// Slicer's); needed when it holds several.
    #[arg(long)]
    label: Option<String>,
    /// Where the laparoscope looks from: X,Y,Z in the surface's unit and frame (a labelmap's: mm,
    /// its scanner frame), or a points file of one point (.csv, 3D Slicer's .fcsv or .mrk.json).
    #[arg(long, value_parser = parse_camera, allow_hyphen_values = true)]
    camera: CameraAt,
    /// Landmarks where the organ is held (ligaments, the hilum): CSV with a header x, y, z, or
    /// 3D Slicer's .fcsv or .mrk.json (in the frame and unit they name).
    #[arg(long, value_name = "LANDMARKS")]
    attach: PathBuf,
    /// Surface nodes within this distance (mm) of a landmark are held [default: the distance that
    /// holds 12 % of the organ's surface, as SOFA's liver scenario does]
    #[arg(long)]
    attach_mm: Option<f64>,
    /// The targets at rest (tumour, vessels): CSV with a header x, y, z, or .fcsv or .mrk.json
    /// (their labels are kept).
    #[arg(long, value_name = "TARGETS")]
    targets: PathBuf,
    /// A structure inside the organ (a tumour, vessels) that the set-up's registrations give back
    /// moved with it: a surface (in the surface's unit and frame, else those its header names) or
    /// LABELMAP:LABEL (Segmentation.seg.nrrd:tumour). Repeat for several.
    #[arg(long = "structure", value_name = "SURFACE")]
    structures: Vec<PathBuf>,
    /// Output directory (resumed when it holds a preparation of the same inputs).
    #[arg(short, long)]
    out: PathBuf,
    /// Unit of the surface, camera, landmarks and targets: mm, m, or auto (told from the
    /// surface's size).
    #[arg(long, default_value = "auto", value_parser = mesh::length::parse_unit_or_auto)]
    units: mesh::length::UnitOrAuto,
    /// FEM draws of the dataset.
    #[arg(long, default_value_t = 2000)]
    samples: usize,
    /// The learned model: rom (the reduced-order model) or unet.
    #[arg(long, default_value = "rom")]
    method: learn::Method,
    /// Tetrahedra of the organ's mesh (about).
    #[arg(long, default_value_t = 3000)]
    tets: usize,
}

/// `X,Y,Z` as three numbers, or else a file.
fn parse_camera(text: &str) -> Result<CameraAt, String> {
    let values: Vec<f64> = match text.split(',').map(|v| v.trim().parse::<f64>()).collect() {
        Ok(values) => values,
        Err(_) if std::path::Path::new(text).is_file() => return Ok(CameraAt::File(PathBuf::from(text))),
        Err(e) => return Err(format!("expected X,Y,Z or a points file, got {text:?} ({e})")),
    };
    <[f64; 3]>::try_from(values).map(CameraAt::Point).map_err(|v| format!("expected X,Y,Z, got {} values", v.len()))
}

/// Prints the steps, with a bar and the time left over the dataset's draws and the training.
struct Printer {
    start: Instant,
    bar: Bar,
}

impl learn::Progress for Printer {
    fn advance(&self, done: u64, total: u64, note: &str) {
        self.bar.advance(done, total, note);
    }

    fn line(&self, text: &str) {
        self.bar.line(text);
    }
}

impl PrepareProgress for Printer {
    fn step(&self, index: usize, name: &str) {
        let at = self.start.elapsed().as_secs_f64();
        self.bar.print(&format!("step {}/{} {name} (at {at:.0} s)", index + 1, STEPS.len()));
    }
}

/// Runs `augsim prepare`.
pub fn run(args: &PrepareArgs) -> Result<()> {
    let mut options =
        PrepareOptions::new(args.surface.clone(), args.camera.clone(), args.attach.clone(), args.targets.clone());
    options.units = args.units;
    options.label = args.label.clone();
    options.structures.clone_from(&args.structures);
    options.attach_distance = args.attach_mm.map(mesh::length::from_mm);
    options.samples = args.samples;
    options.method = args.method;
    options.tets = args.tets;
    let printer = Printer { start: Instant::now(), bar: Bar::new("", "           ") };
    let state = prepare(&options, &args.out, &printer)?;
    printer.bar.finish();
    let total: f64 = state.steps.iter().map(|s| s.seconds).sum();
    println!("time       {total:.0} s over the steps ({} s this run)", printer.start.elapsed().as_secs());
    println!("wrote      {} (report.md; register with `augsim register CLOUD --patient {0}`)", args.out.display());
    Ok(())
}
