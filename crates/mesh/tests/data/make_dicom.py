"""Writes the liver phantom's labelmap (liver_labels.seg.nrrd) as DICOM by independent writers, over
a synthetic CT series of the same geometry (pip install highdicom rt-utils):
- liver_labels_seg.dcm: a DICOM SEG made by highdicom; segments 1 `liver` (label 5 of the
  labelmap) and 2 `kidney` (label 2); empty frames omitted, as highdicom does by default;
- liver_labels_seg_rle.dcm: the liver alone as a FRACTIONAL DICOM SEG (1.0 inside) by highdicom,
  RLE Lossless compressed (what highdicom compresses: not BINARY frames);
- liver_labels_rt.dcm: an RT Structure Set made by rt-utils (as TotalSegmentator writes one); ROIs
  `liver` and `kidney`, contours through the centres of each slice's boundary pixels (OpenCV).

    python make_dicom.py   # in this folder
"""

import gzip
import tempfile
from pathlib import Path

import highdicom as hd
import numpy as np
from rt_utils import RTStructBuilder
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sr.codedict import codes
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, RLELossless, generate_uid

here = Path(__file__).parent
raw = (here / "liver_labels.seg.nrrd").read_bytes()
header, data = raw.split(b"\n\n", 1)
fields = dict(line.split(": ", 1) for line in header.decode().splitlines()[1:] if ": " in line)
nx, ny, nz = map(int, fields["sizes"].split())
origin = [float(v) for v in fields["space origin"].strip("()").split(",")]
labels = np.frombuffer(gzip.decompress(data), dtype="<i2").reshape(nz, ny, nx)
# The labelmap's axes (LPS): i along +x every 1.5 mm, j along -y every 1.5 mm, k along +z every 4 mm.
series, study, frame_of_reference = generate_uid(), generate_uid(), generate_uid()
ct = []
for k in range(nz):
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = CTImageStorage
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    s = Dataset()
    s.file_meta = meta
    s.SOPClassUID, s.SOPInstanceUID = CTImageStorage, meta.MediaStorageSOPInstanceUID
    s.StudyInstanceUID, s.SeriesInstanceUID, s.FrameOfReferenceUID = study, series, frame_of_reference
    s.Modality, s.PatientID, s.PatientName, s.PatientSex, s.PatientBirthDate = "CT", "phantom", "Phantom^Liver", "O", ""
    s.StudyDate, s.StudyTime, s.StudyID, s.AccessionNumber, s.ReferringPhysicianName = "20260101", "120000", "1", "", ""
    s.SeriesNumber, s.InstanceNumber, s.Manufacturer = 1, k + 1, "synthetic"
    s.ImagePositionPatient = [origin[0], origin[1], origin[2] + 4.0 * k]
    s.ImageOrientationPatient = [1, 0, 0, 0, -1, 0]
    s.PixelSpacing, s.SliceThickness = [1.5, 1.5], 4.0
    s.Rows, s.Columns = ny, nx
    s.SamplesPerPixel, s.PhotometricInterpretation = 1, "MONOCHROME2"
    s.BitsAllocated, s.BitsStored, s.HighBit, s.PixelRepresentation = 16, 16, 15, 1
    s.PixelData = np.zeros((ny, nx), dtype="<i2").tobytes()
    ct.append(s)

algorithm = hd.AlgorithmIdentificationSequence(
    name="augsim test data", version="1", family=codes.cid7162.ArtificialIntelligence
)


def segment(number, label, code):
    return hd.seg.SegmentDescription(
        segment_number=number,
        segment_label=label,
        segmented_property_category=codes.SCT.Organ,
        segmented_property_type=code,
        algorithm_type=hd.seg.SegmentAlgorithmTypeValues.AUTOMATIC,
        algorithm_identification=algorithm,
    )


mask = np.zeros(labels.shape, dtype=np.uint8)
mask[labels == 5], mask[labels == 2] = 1, 2


def segmentation(pixel_array, kind, segments, series_number, **options):
    """A DICOM SEG of `ct` by highdicom."""
    return hd.seg.Segmentation(
        source_images=ct,
        pixel_array=pixel_array,
        segmentation_type=kind,
        segment_descriptions=segments,
        series_instance_uid=generate_uid(),
        series_number=series_number,
        sop_instance_uid=generate_uid(),
        instance_number=1,
        manufacturer="augsim",
        manufacturer_model_name="test data",
        software_versions="1",
        device_serial_number="1",
        **options,
    )


liver, kidney = segment(1, "liver", codes.SCT.Liver), segment(2, "kidney", codes.SCT.Kidney)
seg = segmentation(mask, hd.seg.SegmentationTypeValues.BINARY, [liver, kidney], 2)
seg.save_as(here / "liver_labels_seg.dcm")
print(f"{seg.NumberOfFrames} frames, {(here / 'liver_labels_seg.dcm').stat().st_size} bytes")
fractional = segmentation(
    (labels == 5).astype(np.float32),
    hd.seg.SegmentationTypeValues.FRACTIONAL,
    [liver],
    3,
    transfer_syntax_uid=RLELossless,
)
fractional.save_as(here / "liver_labels_seg_rle.dcm")
print(f"RLE: {(here / 'liver_labels_seg_rle.dcm').stat().st_size} bytes")

# rt-utils reads the series from files and orders the slices along their normal (-z here, as the
# rows run along -y): slice s of its mask is the labelmap's k = nz - 1 - s.
with tempfile.TemporaryDirectory() as series_folder:
    for k, s in enumerate(ct):
        s.save_as(Path(series_folder) / f"ct{k:03d}.dcm", enforce_file_format=True)
    rt = RTStructBuilder.create_new(dicom_series_path=series_folder)
    along_normal = labels[::-1].transpose(1, 2, 0)
    rt.add_roi(mask=along_normal == 5, name="liver")
    rt.add_roi(mask=along_normal == 2, name="kidney")
    rt.save(str(here / "liver_labels_rt.dcm"))
print(f"RT structure set: {(here / 'liver_labels_rt.dcm').stat().st_size} bytes")
