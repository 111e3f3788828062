"""Writes liver_labels_seg.dcm: the liver phantom's labelmap (liver_labels.seg.nrrd) as a DICOM SEG
made by highdicom, an independent writer (pip install highdicom), over a synthetic CT series of the
same geometry. Its segments: 1 `liver` (label 5 of the labelmap), 2 `kidney` (label 2); empty
frames omitted, as highdicom does by default.

    python make_dicom_seg.py   # in this folder
"""

import gzip
from pathlib import Path

import highdicom as hd
import numpy as np
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sr.codedict import codes
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

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
seg = hd.seg.Segmentation(
    source_images=ct,
    pixel_array=mask,
    segmentation_type=hd.seg.SegmentationTypeValues.BINARY,
    segment_descriptions=[segment(1, "liver", codes.SCT.Liver), segment(2, "kidney", codes.SCT.Kidney)],
    series_instance_uid=generate_uid(),
    series_number=2,
    sop_instance_uid=generate_uid(),
    instance_number=1,
    manufacturer="augsim",
    manufacturer_model_name="test data",
    software_versions="1",
    device_serial_number="1",
)
seg.save_as(here / "liver_labels_seg.dcm")
print(f"{seg.NumberOfFrames} frames, {(here / 'liver_labels_seg.dcm').stat().st_size} bytes")
