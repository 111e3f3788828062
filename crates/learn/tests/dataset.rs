//! .npy files and sharded datasets: round trips, resume, merge, statistics, corruption errors.

mod common;

use std::path::{Path, PathBuf};

use augsim_learn::data::dataset::MANIFEST_FILE;
use augsim_learn::{merge_datasets, Dataset, DatasetPart, DatasetSpec, DatasetWriter, GridShape, LearnError, Samples};
use common::synthetic_sample;
use mesh::io::npy::{self, NpyData};

fn grid() -> GridShape {
    GridShape::new(6, 5, 4)
}

fn spec(shard_size: usize, part: Option<DatasetPart>) -> DatasetSpec {
    DatasetSpec {
        scenario: "test".into(),
        seed: 7,
        part,
        grid: grid(),
        input_unit: augsim_learn::FieldUnit::Newton,
        target_unit: augsim_learn::FieldUnit::Metre,
        shard_size,
        metadata: serde_json::json!({"young_modulus": 5000.0}),
    }
}

/// Writes samples `indices` (indices divisible by 7 fail) and finishes.
fn write(dir: &Path, spec: DatasetSpec, indices: impl Iterator<Item = u64>) {
    let mut w = DatasetWriter::create_or_resume(dir, spec).unwrap();
    for i in indices {
        push(&mut w, i);
    }
    w.finish().unwrap();
}

fn push(w: &mut DatasetWriter, i: u64) {
    if i % 7 == 3 {
        w.push_failure(i, format!("no convergence at {i}")).unwrap();
    } else {
        w.push(&synthetic_sample(grid(), i)).unwrap();
    }
}

/// All files of a dataset directory with their bytes, sorted by relative path.
fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((p.strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn npy_round_trip_and_header() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.npy");
    let data: Vec<f32> = (0..60).map(|i| i as f32 * 0.37 - 3.0).collect();
    npy::write_f32(&p, &[3, 4, 5], &data).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + header_len) % 64, 0, "data must start on a 64-byte boundary");
    assert_eq!(bytes.len(), 10 + header_len + 60 * 4);
    let a = npy::read_npy(&p).unwrap();
    assert_eq!(a.shape, vec![3, 4, 5]);
    assert_eq!(a.data, NpyData::F32(data));

    let q = dir.path().join("m.npy");
    npy::write_u8(&q, &[7], &[0, 1, 1, 0, 1, 0, 0]).unwrap();
    let m = npy::read_npy(&q).unwrap();
    assert_eq!(m.shape, vec![7]);
    assert_eq!(m.data, NpyData::U8(vec![0, 1, 1, 0, 1, 0, 0]));
    assert_eq!(npy::read_shape(&q).unwrap(), vec![7]);
    // A file cut short: its shape is refused too, not only its data.
    let bytes = std::fs::read(&q).unwrap();
    std::fs::write(&q, &bytes[..bytes.len() - 3]).unwrap();
    let e = npy::read_shape(&q).unwrap_err().to_string();
    assert!(e.contains("truncated: shape [7] of |u1 needs 7 data bytes, the file has 4"), "{e}");
}

/// An .npy file as numpy writes it (v1.0 header padded to 64 bytes).
fn numpy_file(descr: &str, fortran: &str, shape: &str, data: &[u8]) -> Vec<u8> {
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': {fortran}, 'shape': {shape}, }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    bytes.extend_from_slice(dict.as_bytes());
    bytes.extend_from_slice(data);
    bytes
}

#[test]
fn npy_reads_numpy_f64_and_rejects_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    // np.array([[1.5, -2.0]]) saved by numpy (float64).
    let data: Vec<u8> = [1.5f64, -2.0].iter().flat_map(|x| x.to_le_bytes()).collect();
    let bytes = numpy_file("<f8", "False", "(1, 2)", &data);
    let p = dir.path().join("f8.npy");
    std::fs::write(&p, &bytes).unwrap();
    let a = npy::read_npy(&p).unwrap();
    assert_eq!(a.shape, vec![1, 2]);
    assert_eq!(a.into_f32(), vec![1.5, -2.0]);
    // A bool mask (np.bool_) of shape (3,).
    std::fs::write(&p, numpy_file("|b1", "False", "(3,)", &[1, 0, 1])).unwrap();
    assert_eq!(npy::read_npy(&p).unwrap().into_mask(&p).unwrap(), vec![1, 0, 1]);

    // Truncated data.
    std::fs::write(&p, &bytes[..bytes.len() - 3]).unwrap();
    let e = npy::read_npy(&p).unwrap_err().to_string();
    assert!(e.contains("f8.npy") && e.contains("truncated"), "{e}");
    // Trailing bytes.
    let mut longer = bytes.clone();
    longer.push(0);
    std::fs::write(&p, &longer).unwrap();
    assert!(npy::read_npy(&p).unwrap_err().to_string().contains("trailing"));
    // A shape whose byte count wraps around to the data's (2^61 + 1 rows of 2 f8: 2^65 + 16 bytes).
    std::fs::write(&p, numpy_file("<f8", "False", "(2305843009213693953, 2)", &data)).unwrap();
    let e = npy::read_npy(&p).unwrap_err().to_string();
    assert!(e.contains("more bytes than any file can"), "{e}");
    // Not an npy file.
    std::fs::write(&p, b"hello world, this is text").unwrap();
    let e = npy::read_npy(&p).unwrap_err().to_string();
    assert!(e.contains("magic"), "{e}");
    // Unsupported dtypes.
    for descr in ["<c16", "<f2", "<U3", "O"] {
        std::fs::write(&p, numpy_file(descr, "False", "(1, 2)", &data)).unwrap();
        assert!(npy::read_npy(&p).unwrap_err().to_string().contains("unsupported dtype"), "{descr}");
    }
}

/// `np.save` of a transposed array writes Fortran order, of big-endian or integer data their
/// own dtype: each is read back in C order as the same values.
#[test]
fn npy_reads_fortran_order_big_endian_and_integers() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.npy");
    // The array [[1, 2, 3], [4, 5, -6]] (shape (2, 3)), in C order.
    let values = [1.0, 2.0, 3.0, 4.0, 5.0, -6.0];
    let fortran = [1.0, 4.0, 2.0, 5.0, 3.0, -6.0];
    let f8 = |v: &[f64], big: bool| -> Vec<u8> {
        v.iter().flat_map(|x| if big { x.to_be_bytes() } else { x.to_le_bytes() }).collect()
    };
    let cases: Vec<(&str, &str, Vec<u8>)> = vec![
        ("<f8", "True", f8(&fortran, false)),
        (">f8", "False", f8(&values, true)),
        (">f8", "True", f8(&fortran, true)),
        ("<i8", "False", values.iter().flat_map(|&x| (x as i64).to_le_bytes()).collect()),
        (">i4", "True", fortran.iter().flat_map(|&x| (x as i32).to_be_bytes()).collect()),
        ("<i2", "False", values.iter().flat_map(|&x| (x as i16).to_le_bytes()).collect()),
        ("<f4", "True", fortran.iter().flat_map(|&x| (x as f32).to_le_bytes()).collect()),
    ];
    for (descr, order, bytes) in cases {
        std::fs::write(&p, numpy_file(descr, order, "(2, 3)", &bytes)).unwrap();
        let a = npy::read_npy(&p).unwrap();
        assert_eq!(a.shape, vec![2, 3], "{descr} {order}");
        assert_eq!(a.into_f64(), values, "{descr}, Fortran order {order}");
    }
    // Three axes in Fortran order: element (i, j, k) at i + 2 j + 4 k.
    let shape = [2usize, 2, 3];
    let c_order: Vec<f64> = (0..12).map(f64::from).collect();
    let mut stored = vec![0.0; 12];
    for i in 0..2 {
        for j in 0..2 {
            for k in 0..3 {
                stored[i + 2 * j + 4 * k] = c_order[(i * 2 + j) * 3 + k];
            }
        }
    }
    std::fs::write(&p, numpy_file("<f8", "True", "(2, 2, 3)", &f8(&stored, false))).unwrap();
    let a = npy::read_npy(&p).unwrap();
    assert_eq!((a.shape.clone(), a.into_f64()), (shape.to_vec(), c_order));
}

#[test]
fn write_read_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), spec(4, None), 0..11);
    let ds = Dataset::open(dir.path()).unwrap();
    let m = ds.manifest();
    assert!(m.complete);
    assert_eq!(m.failed.iter().map(|f| f.index).collect::<Vec<_>>(), vec![3, 10]);
    assert_eq!(m.num_samples, 9);
    assert_eq!(m.shards.len(), 3);
    assert_eq!(m.shards.iter().map(|s| s.num_samples).collect::<Vec<_>>(), vec![4, 4, 1]);
    assert_eq!(m.next_index, 11);
    assert_eq!(m.units.input, augsim_learn::FieldUnit::Newton);
    let all = ds.load_all().unwrap();
    let expected: Vec<u64> = (0..11).filter(|i| i % 7 != 3).collect();
    assert_eq!(all.indices, expected);
    for (pos, &i) in expected.iter().enumerate() {
        assert_eq!(all.get(pos), synthetic_sample(grid(), i), "sample {i}");
    }
    // Ranges crossing shard boundaries, and the train/test split.
    let part = ds.load_range(3..6).unwrap();
    assert_eq!(part.indices, expected[3..6].to_vec());
    let (train, test) = all.clone().split_at(6).unwrap();
    assert_eq!(train, ds.load_range(0..6).unwrap());
    assert_eq!(test, ds.load_range(6..9).unwrap());
    assert!(ds.load_range(5..10).is_err());
}

/// A shard whose arrays were changed after it was written (every node masked, targets in mm, the
/// inputs and targets swapped) is refused as it is loaded, naming its file: it no longer gives the
/// sums its manifest recorded.
#[test]
fn a_shard_changed_since_it_was_written_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), spec(4, None), 0..5);
    let shard = ds_shard(dir.path());
    let [nx, ny, nz] = grid().dims();
    let read = |name: &str| npy::read_npy(&shard.join(name)).unwrap();
    let (inputs, targets, masks) = (read("inputs.npy"), read("targets.npy"), read("masks.npy"));
    let field = [4, 3, nx, ny, nz];
    /// What a change makes the error say, and the change.
    type Change<'a> = (&'a str, Box<dyn Fn() + 'a>);
    let changes: [Change; 3] = [
        (
            "masks.npy: its masked nodes",
            Box::new(|| npy::write_u8(&shard.join("masks.npy"), &[4, nx, ny, nz], &vec![1; 4 * nx * ny * nz]).unwrap()),
        ),
        (
            "targets.npy: its sums of the targets",
            Box::new(|| {
                let mm: Vec<f32> = targets.clone().into_f32().iter().map(|v| 1000.0 * v).collect();
                npy::write_f32(&shard.join("targets.npy"), &field, &mm).unwrap()
            }),
        ),
        (
            "inputs.npy: its nodes with an input",
            Box::new(|| {
                npy::write_f32(&shard.join("inputs.npy"), &field, &targets.clone().into_f32()).unwrap();
                npy::write_f32(&shard.join("targets.npy"), &field, &inputs.clone().into_f32()).unwrap()
            }),
        ),
    ];
    for (said, change) in changes {
        change();
        let e = Dataset::open(dir.path()).unwrap().load_all().unwrap_err().to_string();
        assert!(e.contains(said) && e.contains("differ from those") && e.contains("manifest.json"), "{e}");
        npy::write_f32(&shard.join("inputs.npy"), &field, &inputs.clone().into_f32()).unwrap();
        npy::write_f32(&shard.join("targets.npy"), &field, &targets.clone().into_f32()).unwrap();
        npy::write_u8(&shard.join("masks.npy"), &[4, nx, ny, nz], &masks.clone().into_mask(&shard).unwrap()).unwrap();
        assert!(Dataset::open(dir.path()).unwrap().load_all().is_ok(), "restored");
    }
}

/// The folder of a dataset's first shard.
fn ds_shard(dir: &Path) -> PathBuf {
    let masks = Dataset::open(dir).unwrap().manifest().shards[0].masks.clone();
    dir.join(Path::new(&masks).parent().unwrap())
}

#[test]
fn statistics_match_hand_computation() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), spec(2, None), 0..5);
    let ds = Dataset::open(dir.path()).unwrap();
    let all = ds.load_all().unwrap();
    let n = grid().nodes();
    let (mut cnt_in, mut sum_in, mut sq_in) = (0u64, [0f64; 3], 0f64);
    let (mut cnt_t, mut sum_t, mut sq_t) = (0u64, [0f64; 3], [0f64; 3]);
    for s in 0..all.len() {
        let (inp, tgt, mask) = (all.input(s), all.target(s), all.mask(s));
        for v in 0..n {
            if (0..3).any(|c| inp[c * n + v] != 0.0) {
                cnt_in += 1;
                for c in 0..3 {
                    sum_in[c] += inp[c * n + v] as f64;
                    sq_in += (inp[c * n + v] as f64).powi(2);
                }
            }
            if mask[v] == 1 {
                cnt_t += 1;
                for c in 0..3 {
                    sum_t[c] += tgt[c * n + v] as f64;
                    sq_t[c] += (tgt[c * n + v] as f64).powi(2);
                }
            }
        }
    }
    let st = ds.manifest().statistics;
    assert_eq!(st.inputs.nodes, cnt_in);
    assert_eq!(st.targets.nodes, cnt_t);
    assert!(cnt_in == 8 * 4, "each of the 4 samples loads a 2x2x2 patch");
    for c in 0..3 {
        assert!((st.inputs.mean[c] - sum_in[c] / cnt_in as f64).abs() < 1e-12);
        let mean = sum_t[c] / cnt_t as f64;
        let std = (sq_t[c] / cnt_t as f64 - mean * mean).sqrt();
        assert!((st.targets.std[c] - std).abs() < 1e-12);
    }
    assert!((st.inputs.rms_norm - (sq_in / cnt_in as f64).sqrt()).abs() < 1e-12);
    let norm = augsim_learn::Normalization::from_statistics(&st);
    assert_eq!(norm.input_scale, st.inputs.rms_norm);

    // The statistics of loaded samples are the manifest's (which sums shard by shard), and
    // those of a subset (a training split) its own.
    let loaded = all.statistics();
    assert_eq!((loaded.inputs.nodes, loaded.targets.nodes), (st.inputs.nodes, st.targets.nodes));
    assert!((loaded.targets.rms_norm - st.targets.rms_norm).abs() < 1e-12 * st.targets.rms_norm);
    let first = all.select(&[0]).unwrap().statistics();
    assert_eq!(first.inputs.nodes, 8);
    assert_ne!(first.targets.rms_norm, st.targets.rms_norm);
}

#[test]
fn the_source_names_the_samples_not_the_dataset_size() {
    let (a, b, c) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    write(a.path(), spec(4, None), 0..11);
    write(b.path(), spec(2, None), 0..5);
    write(c.path(), DatasetSpec { seed: 8, ..spec(4, None) }, 0..11);
    let source = |d: &Path| Dataset::open(d).unwrap().manifest().source_id();
    assert_eq!(source(a.path()), source(b.path()), "fewer samples and other shards: the same samples");
    assert_ne!(source(a.path()), source(c.path()), "another seed: other samples");
    let loaded = Dataset::open(a.path()).unwrap().load_range(2..5).unwrap();
    assert_eq!(loaded.source, Some(source(a.path())));
    // Samples of different sources do not mix.
    let mut mixed = loaded.clone();
    assert!(mixed.append(Dataset::open(c.path()).unwrap().load_range(0..1).unwrap()).is_err());
}

/// A dataset has one writer at a time: a second is refused while the first writes (its draws
/// would mix with the first's), and may go on once the first has stopped (killed: dropped here).
#[test]
fn a_second_writer_is_refused_while_the_first_writes() {
    let dir = tempfile::tempdir().unwrap();
    let mut first = DatasetWriter::create_or_resume(dir.path(), spec(3, None)).unwrap();
    push(&mut first, 0);
    let refused = |e: LearnError| e.to_string().contains("is being written by another run");
    assert!(DatasetWriter::create_or_resume(dir.path(), spec(3, None)).err().is_some_and(refused));
    assert!(DatasetWriter::append(dir.path(), &spec(3, None)).err().is_some_and(refused));
    drop(first);
    let mut second = DatasetWriter::create_or_resume(dir.path(), spec(3, None)).unwrap();
    push(&mut second, 0);
    second.finish().unwrap();
    assert!(!dir.path().join(augsim_learn::data::dataset::WRITER_LOCK).exists(), "removed when finished");
}

#[test]
fn resumed_writing_equals_uninterrupted() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    write(a.path(), spec(3, None), 0..13);

    // Interrupted: the writer is dropped (a crash) after 11 indices: 3 shards committed (9
    // samples and the failure 3), the failure 10 pending and lost.
    let mut w = DatasetWriter::create_or_resume(b.path(), spec(3, None)).unwrap();
    for i in 0..11 {
        push(&mut w, i);
    }
    drop(w);
    let mut w = DatasetWriter::create_or_resume(b.path(), spec(3, None)).unwrap();
    let from = w.resume_from();
    assert_eq!(from, 10, "indices 0..10 hold 9 samples + the failure 3: three shards of 3");
    for i in from..13 {
        push(&mut w, i);
    }
    w.finish().unwrap();
    assert_eq!(tree(a.path()), tree(b.path()));

    // A complete dataset is not resumed, and a different spec is refused.
    let e = DatasetWriter::create_or_resume(b.path(), spec(3, None)).err().unwrap().to_string();
    assert!(e.contains("already complete"), "{e}");
    let c = tempfile::tempdir().unwrap();
    drop(DatasetWriter::create_or_resume(c.path(), spec(3, None)).unwrap());
    let e = DatasetWriter::create_or_resume(c.path(), spec(4, None)).err().unwrap().to_string();
    assert!(e.contains("cannot resume"), "{e}");
}

/// A spec asking for `samples` samples, as the generator records it.
fn counted_spec(samples: u64) -> DatasetSpec {
    DatasetSpec { metadata: serde_json::json!({"dataset": {"samples": samples, "cone": 90.0}}), ..spec(3, None) }
}

#[test]
fn a_complete_dataset_grows_when_asked_for_more_samples() {
    let (grown, whole) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    write(grown.path(), counted_spec(8), 0..8);
    write(whole.path(), counted_spec(13), 0..13);
    let mut w = DatasetWriter::create_or_resume(grown.path(), counted_spec(13)).unwrap();
    assert_eq!(w.resume_from(), 8, "generation goes on after the samples held");
    for i in 8..13 {
        push(&mut w, i);
    }
    w.finish().unwrap();
    let (a, b) = (Dataset::open(grown.path()).unwrap(), Dataset::open(whole.path()).unwrap());
    assert_eq!(a.manifest().spec(), b.manifest().spec());
    assert_eq!(a.manifest().failed, b.manifest().failed);
    let (x, y) = (a.load_all().unwrap(), b.load_all().unwrap());
    assert_eq!((&x.indices, &x.inputs, &x.targets, &x.masks), (&y.indices, &y.inputs, &y.targets, &y.masks));
    assert_eq!(x.source, y.source);
    // Fewer samples, or more of another spec, are no growth.
    let e = DatasetWriter::create_or_resume(grown.path(), counted_spec(10)).err().unwrap().to_string();
    assert!(
        e.contains("cannot resume: it was made for 13 draws: --samples grows a dataset but does not shrink"),
        "{e}"
    );
    let other =
        DatasetSpec { metadata: serde_json::json!({"dataset": {"samples": 20, "cone": 180.0}}), ..spec(3, None) };
    let e = DatasetWriter::create_or_resume(grown.path(), other).err().unwrap().to_string();
    let differences = "metadata.dataset.cone 90.0 there, 180.0 now; metadata.dataset.samples 13 there, 20 now";
    assert!(e.contains(&format!("cannot resume: it was created otherwise ({differences})")), "{e}");
    // The seed, recorded in the spec and in the generator's metadata, is told once.
    let seeded =
        |seed: u64| DatasetSpec { seed, metadata: serde_json::json!({"dataset": {"seed": seed}}), ..spec(3, None) };
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), seeded(7), 0..2);
    let e = DatasetWriter::create_or_resume(dir.path(), seeded(8)).err().unwrap().to_string();
    assert!(e.contains("cannot resume: it was created otherwise (seed 7 there, 8 now)"), "{e}");
}

#[test]
fn writer_rejects_bad_samples() {
    let dir = tempfile::tempdir().unwrap();
    let mut w = DatasetWriter::create_or_resume(dir.path(), spec(3, None)).unwrap();
    w.push(&synthetic_sample(grid(), 5)).unwrap();
    assert!(w.push(&synthetic_sample(grid(), 5)).is_err(), "indices must increase");
    assert!(w.push_failure(2, "late").is_err());
    let mut s = synthetic_sample(grid(), 6);
    s.target.pop();
    let e = w.push(&s).unwrap_err().to_string();
    assert!(e.contains("target has"), "{e}");
    let mut s = synthetic_sample(grid(), 7);
    s.input[0] = f32::NAN;
    assert!(w.push(&s).is_err());
}

#[test]
fn merge_of_worker_parts_equals_single_writer() {
    let root = tempfile::tempdir().unwrap();
    let single = root.path().join("single");
    write(&single, spec(4, None), 0..15);
    let parts: Vec<PathBuf> = (0..3).map(|w| root.path().join(format!("part{w}"))).collect();
    for (w, dir) in parts.iter().enumerate() {
        // Worker w of 3 takes the indices i with i % 3 == w, with its own shard size.
        write(dir, spec(2, Some(DatasetPart { index: w, count: 3 })), (0..15).filter(|i| i % 3 == w as u64));
    }
    let merged = root.path().join("merged");
    merge_datasets(&parts, &merged, Some(4)).unwrap();
    assert_eq!(tree(&single), tree(&merged));
    let e = merge_datasets(&parts, &merged, Some(4)).unwrap_err().to_string();
    assert!(e.contains("merge output already holds a dataset"), "{e}");

    // A merge killed after two shards (its writer gone, its lock file left) goes on when run again.
    let killed = root.path().join("killed");
    let mut w = DatasetWriter::create_or_resume(&killed, spec(4, None)).unwrap();
    (0..10).for_each(|i| push(&mut w, i));
    drop(w);
    std::fs::write(killed.join(augsim_learn::data::dataset::WRITER_LOCK), b"").unwrap();
    merge_datasets(&parts, &killed, Some(4)).unwrap();
    assert_eq!(tree(&single), tree(&killed));

    // A part given twice, or one missing (its draws would be left out of a "complete" dataset),
    // is refused.
    let dup = root.path().join("dup");
    let twice = [parts.clone(), vec![parts[0].clone()]].concat();
    let e = merge_datasets(&twice, &dup, None).unwrap_err().to_string();
    assert!(e.contains("part(s) 0/3 are given more than once"), "{e}");
    let e = merge_datasets(&[parts[0].clone(), parts[2].clone()], &dup, None).unwrap_err().to_string();
    assert!(e.contains("part(s) 1/3 of the split generation are missing"), "{e}");
    assert!(!dup.join("manifest.json").exists(), "nothing written");
    // An unfinished part is refused.
    let open = root.path().join("open");
    drop(DatasetWriter::create_or_resume(&open, spec(2, Some(DatasetPart { index: 0, count: 3 }))).unwrap());
    let e = merge_datasets(&[parts[1].clone(), open], &root.path().join("m2"), None).unwrap_err().to_string();
    assert!(e.contains("not complete"), "{e}");
    // A part generated for another count is named with what differs, not with all that must agree.
    let other = root.path().join("other");
    let asked = |spec: DatasetSpec| DatasetSpec {
        metadata: serde_json::json!({"young_modulus": 5000.0, "dataset": {"samples": 30}}),
        ..spec
    };
    write(&other, asked(spec(2, Some(DatasetPart { index: 1, count: 3 }))), (0..15).filter(|i| i % 3 == 1));
    let given = [parts[0].clone(), other, parts[2].clone()];
    let e = merge_datasets(&given, &root.path().join("m3"), None).unwrap_err().to_string();
    assert!(e.contains("metadata.dataset null there, {\"samples\":30} now; scenario, seed"), "{e}");
}

#[test]
fn corrupt_shards_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), spec(4, None), 0..6);
    let ds = Dataset::open(dir.path()).unwrap();
    let inputs = dir.path().join("shard_00001/inputs.npy");

    // Truncated inputs.
    let bytes = std::fs::read(&inputs).unwrap();
    std::fs::write(&inputs, &bytes[..bytes.len() - 10]).unwrap();
    let e = ds.load_all().unwrap_err();
    assert!(matches!(e, LearnError::Mesh(mesh::MeshError::Parse { .. })));
    let e = e.to_string();
    assert!(e.contains("shard_00001/inputs.npy") && e.contains("truncated"), "{e}");
    std::fs::write(&inputs, &bytes).unwrap();
    assert!(ds.load_all().is_ok());

    // A masks file with the wrong shape (one sample fewer than the manifest says).
    let masks = dir.path().join("shard_00000/masks.npy");
    let saved = std::fs::read(&masks).unwrap();
    let n = grid().nodes();
    npy::write_u8(&masks, &[3, 6, 5, 4], &vec![1u8; 3 * n]).unwrap();
    let e = ds.load_all().unwrap_err().to_string();
    assert!(e.contains("shard_00000/masks.npy") && e.contains("does not match the manifest"), "{e}");
    assert!(ds.check_files().is_err());
    std::fs::write(&masks, &saved).unwrap();

    // Mask values other than 0/1.
    npy::write_u8(&masks, &[4, 6, 5, 4], &vec![2u8; 4 * n]).unwrap();
    let e = ds.load_shard(0).unwrap_err().to_string();
    assert!(e.contains("0 or 1"), "{e}");
    std::fs::write(&masks, &saved).unwrap();

    // A NaN, or a value no organ's displacement or force comes near, in a target or an input:
    // named by file, sample, draw and place, not trained on.
    let targets = dir.path().join("shard_00001/targets.npy");
    let saved = std::fs::read(&targets).unwrap();
    let shard = ds.load_shard(1).unwrap();
    let (mut values, draw) = (shard.targets, shard.indices[0]);
    let shape = [1, 3, 6, 5, 4];
    values[7] = f32::NAN;
    npy::write_f32(&targets, &shape, &values).unwrap();
    let e = ds.load_all().unwrap_err().to_string();
    assert!(
        e.contains("shard_00001/targets.npy") && e.contains(&format!("sample 0 (draw {draw}), value 7 is NaN")),
        "{e}"
    );
    values[7] = 1e30;
    npy::write_f32(&targets, &shape, &values).unwrap();
    let e = ds.load_shard(1).unwrap_err().to_string();
    assert!(e.contains("value 7 is 1e30") && e.contains("is the file damaged?"), "{e}");
    std::fs::write(&targets, &saved).unwrap();

    // A manifest whose counts disagree.
    let mp = dir.path().join(MANIFEST_FILE);
    let text = std::fs::read_to_string(&mp).unwrap();
    std::fs::write(&mp, text.replacen("\"num_samples\": 5", "\"num_samples\": 6", 1)).unwrap();
    let e = Dataset::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("manifest.json") && e.contains("num_samples"), "{e}");
    std::fs::write(&mp, "{ not json").unwrap();
    let e = Dataset::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("invalid manifest JSON"), "{e}");
    // A directory without a manifest, and none at all.
    std::fs::remove_file(&mp).unwrap();
    let e = Dataset::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("not a dataset") && e.contains("augsim generate"), "{e}");
    let e = Dataset::open(&dir.path().join("absent")).unwrap_err().to_string();
    assert!(e.contains("absent: no such folder"), "{e}");
    // A file given for the folder.
    std::fs::write(dir.path().join("a_file"), "").unwrap();
    let e = Dataset::open(&dir.path().join("a_file")).unwrap_err().to_string();
    assert!(e.contains("a_file: a file, not a dataset's folder"), "{e}");
}

#[test]
fn samples_select_and_append() {
    let s = common::synthetic_samples(grid(), 0, 4);
    let sel = s.select(&[2, 0]).unwrap();
    assert_eq!(sel.indices, vec![2, 0]);
    assert_eq!(sel.get(0), s.get(2));
    let mut t = Samples::new(grid());
    t.append(sel).unwrap();
    assert_eq!(t.len(), 2);
    assert!(Samples::new(GridShape::new(2, 2, 2)).append(s).is_err());
}

/// A field's unit is written as the files always had it ("N", "m"); any other is refused on
/// reading, naming the two.
#[test]
fn field_units_are_written_n_and_m_and_others_refused() {
    use augsim_learn::FieldUnit;
    assert_eq!(serde_json::to_string(&[FieldUnit::Newton, FieldUnit::Metre]).unwrap(), r#"["N","m"]"#);
    assert_eq!(serde_json::from_str::<FieldUnit>(r#""N""#).unwrap(), FieldUnit::Newton);
    assert!(FieldUnit::Newton.is_force() && !FieldUnit::Metre.is_force());
    let e = serde_json::from_str::<FieldUnit>(r#""kg""#).unwrap_err().to_string();
    assert!(e.contains("unknown variant `kg`, expected `N` or `m`"), "{e}");
}
