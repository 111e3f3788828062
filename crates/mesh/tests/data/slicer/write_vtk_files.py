"""Writes this folder's .vtp, .vtu and .ply files with VTK (`pip install vtk`; they were made with
VTK 9.7.2), through the writers and settings 3D Slicer's model storage node uses: the XML
writers with a String field array SPACE, zlib-compressed and appended (Slicer's default) or in
ASCII (compression off); the PLY writer after a triangle filter, with the comment SPACE=..."""
import vtk

POINTS = [(0, 0, 0), (10, 0, 0), (0, 20, 0), (0, 0, 30)]
TRIANGLES = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def tetrahedron():
    data, points, polys = vtk.vtkPolyData(), vtk.vtkPoints(), vtk.vtkCellArray()
    for p in POINTS:
        points.InsertNextPoint(*p)
    for t in TRIANGLES:
        polys.InsertNextCell(3, t)
    data.SetPoints(points)
    data.SetPolys(polys)
    return data


def name_frame(data, frame):
    space = vtk.vtkStringArray()
    space.SetName("SPACE")
    space.InsertNextValue(frame)
    data.GetFieldData().AddArray(space)
    return data


def write_xml(writer, data, name, compressed):
    writer.SetInputData(data)
    writer.SetFileName(name)
    writer.SetCompressorType(vtk.vtkXMLWriter.ZLIB if compressed else vtk.vtkXMLWriter.NONE)
    writer.SetDataMode(vtk.vtkXMLWriter.Appended if compressed else vtk.vtkXMLWriter.Ascii)
    assert writer.Write() == 1


write_xml(vtk.vtkXMLPolyDataWriter(), name_frame(tetrahedron(), "RAS"), "tetrahedron_ras.vtp", True)
write_xml(vtk.vtkXMLPolyDataWriter(), name_frame(tetrahedron(), "LPS"), "tetrahedron_lps_ascii.vtp", False)
grid = vtk.vtkAppendFilter()
grid.AddInputData(tetrahedron())
grid.Update()
write_xml(vtk.vtkXMLUnstructuredGridWriter(), name_frame(grid.GetOutput(), "LPS"), "tetrahedron_lps.vtu", True)

for file_type, name, frame in [(vtk.VTK_BINARY, "tetrahedron_ras.ply", "RAS"),
                               (vtk.VTK_ASCII, "tetrahedron_lps_ascii.ply", "LPS")]:
    triangles = vtk.vtkTriangleFilter()
    triangles.SetInputData(tetrahedron())
    writer = vtk.vtkPLYWriter()
    writer.SetFileName(name)
    writer.SetFileType(file_type)
    writer.SetInputConnection(triangles.GetOutputPort())
    writer.AddComment("SPACE=" + frame)
    assert writer.Write() == 1

# A cloud saved as a model: three points, a vertex cell each.
cloud, points, verts = vtk.vtkPolyData(), vtk.vtkPoints(), vtk.vtkCellArray()
for i, p in enumerate([(1.5, -2, 3), (4, 5.25, -6), (-7, 8, 9.5)]):
    points.InsertNextPoint(*p)
    verts.InsertNextCell(1, [i])
cloud.SetPoints(points)
cloud.SetVerts(verts)
write_xml(vtk.vtkXMLPolyDataWriter(), name_frame(cloud, "RAS"), "cloud_ras.vtp", True)

# The tetrahedron as one triangle strip (vtkStripper), ASCII, naming no frame.
strips = vtk.vtkStripper()
strips.SetInputData(tetrahedron())
strips.Update()
writer = vtk.vtkXMLPolyDataWriter()
writer.SetInputData(strips.GetOutput())
writer.SetFileName("tetrahedron_strips.vtp")
writer.SetDataModeToAscii()
assert writer.Write() == 1
