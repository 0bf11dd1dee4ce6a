"""Render an `anm-post export` file (vtu, vtp or vtkhdf) offscreen to a PNG with VTK: surfaces
coloured by sieve (anm's VRML palette), shell layers translucent, the box as a wireframe; with
--cut X only the particles whose centre is below x = X (a view into the packing).

    python3 scripts/render_export.py out/msand.vtkhdf docs/figures/msand-export.png --cut 10
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

PALETTE = [(0.55, 0.45, 0.35), (0.75, 0.65, 0.45), (0.85, 0.80, 0.60), (0.60, 0.60, 0.65), (0.45, 0.55, 0.45),
           (0.70, 0.50, 0.50)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input")
    ap.add_argument("png")
    ap.add_argument("--size", type=int, nargs=2, default=(1200, 900))
    ap.add_argument("--cut", type=float, help="keep particles with centre x below this (mm)")
    args = ap.parse_args()

    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    suffix = args.input.rsplit(".", 1)[-1]
    reader = {"vtu": vtk.vtkXMLUnstructuredGridReader, "vtp": vtk.vtkXMLPolyDataReader,
              "vtkhdf": vtk.vtkHDFReader, "hdf": vtk.vtkHDFReader}[suffix]()
    reader.SetFileName(args.input)
    reader.Update()
    data = reader.GetOutput()
    cd = data.GetCellData()
    kind = vtk_to_numpy(cd.GetArray("kind"))
    pid = vtk_to_numpy(cd.GetArray("particle_id"))
    keep = kind == 1
    if args.cut is not None:
        pts = vtk_to_numpy(data.GetPoints().GetData())
        n = int((kind == 0).sum())
        centres = np.array([pts[data.GetCell(i).GetPointId(0)] for i in range(n)])
        keep &= centres[pid, 0] < args.cut
    mask = numpy_to_vtk(keep.astype(np.uint8), deep=True)
    mask.SetName("keep")
    cd.AddArray(mask)
    thr = vtk.vtkThreshold()
    thr.SetInputData(data)
    thr.SetInputArrayToProcess(0, 0, 0, vtk.vtkDataObject.FIELD_ASSOCIATION_CELLS, "keep")
    thr.SetLowerThreshold(0.5)
    thr.SetUpperThreshold(1.5)
    thr.SetThresholdFunction(vtk.vtkThreshold.THRESHOLD_BETWEEN)
    geo = vtk.vtkGeometryFilter()
    geo.SetInputConnection(thr.GetOutputPort())
    normals = vtk.vtkPolyDataNormals()
    normals.SetInputConnection(geo.GetOutputPort())
    normals.SplittingOff()

    lut = vtk.vtkLookupTable()
    lut.SetNumberOfTableValues(len(PALETTE))
    for i, c in enumerate(PALETTE):
        lut.SetTableValue(i, *c, 1.0)
    lut.SetTableRange(0, len(PALETTE) - 1)
    mapper = vtk.vtkPolyDataMapper()
    mapper.SetInputConnection(normals.GetOutputPort())
    mapper.SetScalarModeToUseCellFieldData()
    mapper.SelectColorArray("sieve")
    mapper.SetLookupTable(lut)
    mapper.SetScalarRange(0, len(PALETTE) - 1)
    mapper.ScalarVisibilityOn()
    actor = vtk.vtkActor()
    actor.SetMapper(mapper)

    ren = vtk.vtkRenderer()
    ren.AddActor(actor)
    outline = vtk.vtkOutlineFilter()
    outline.SetInputData(data)
    om = vtk.vtkPolyDataMapper()
    om.SetInputConnection(outline.GetOutputPort())
    oa = vtk.vtkActor()
    oa.SetMapper(om)
    oa.GetProperty().SetColor(0.2, 0.2, 0.2)
    ren.AddActor(oa)
    ren.SetBackground(1, 1, 1)
    # looking at the box centre from the +x side (the cut face), above and to the side
    bounds = np.array(data.GetBounds()).reshape(3, 2)
    centre = bounds.mean(axis=1)
    span = float((bounds[:, 1] - bounds[:, 0]).max())
    cam = ren.GetActiveCamera()
    cam.SetFocalPoint(*centre)
    cam.SetPosition(*(centre + span * np.array([1.6, -1.1, 1.0])))
    cam.SetViewUp(0, 0, 1)
    ren.ResetCameraClippingRange()
    light = vtk.vtkLight()
    light.SetLightTypeToCameraLight()
    light.SetPosition(0.3, 0.6, 1)
    ren.AddLight(light)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.AddRenderer(ren)
    win.SetSize(*args.size)
    win.Render()
    grab = vtk.vtkWindowToImageFilter()
    grab.SetInput(win)
    grab.Update()
    w = vtk.vtkPNGWriter()
    w.SetFileName(args.png)
    w.SetInputConnection(grab.GetOutputPort())
    w.Write()
    print(f"{args.png}: {int(keep.sum())} surface cells of {len(np.unique(pid[keep]))} particles")
    return 0


if __name__ == "__main__":
    sys.exit(main())
