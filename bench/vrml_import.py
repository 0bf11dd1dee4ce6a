"""Time VTK's VRML importer (vtkVRMLImporter) on scenes of n particles in two node layouts
(docs/vrml.md, issue 17 item 1):

  use:  one DEF'd Shape per kind, each particle a Transform that USEs it (Anm's layout up to
        issue 17);
  flat: one Shape with one IndexedFaceSet per kind holding every particle of that kind, vertices
        already in world coordinates (Anm's layout since).

The meshes are lat-long spheres of `--tess` polar divisions, as anm writes them. Prints a CSV
(layout, particles, seconds, file MB); a layout is skipped at the next size once it took more
than --limit seconds.

    python3 bench/vrml_import.py --sizes 250,500,1000,2000,4000 --tess 8
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np


def sphere(tess: int) -> tuple[np.ndarray, list[list[int]]]:
    nt, np_ = tess, 2 * tess
    pts = []
    for i in range(1, nt):
        th = np.pi * i / nt
        for j in range(np_):
            ph = 2 * np.pi * j / np_
            pts.append([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
    pts += [[0, 0, 1], [0, 0, -1]]
    north, south = (nt - 1) * np_, (nt - 1) * np_ + 1
    faces = [[north, (j + 1) % np_, j] for j in range(np_)]
    for i in range(nt - 2):
        for j in range(np_):
            faces.append([i * np_ + j, i * np_ + (j + 1) % np_, (i + 1) * np_ + (j + 1) % np_, (i + 1) * np_ + j])
    faces += [[(nt - 2) * np_ + j, (nt - 2) * np_ + (j + 1) % np_, south] for j in range(np_)]
    return np.array(pts), faces


def write(path: str, layout: str, n: int, tess: int, kinds: int = 4) -> None:
    rng = np.random.default_rng(1)
    pts, faces = sphere(tess)
    centers = rng.uniform(0, 20, (n, 3))
    kind = np.arange(n) % kinds
    colour = rng.uniform(0.2, 0.9, (kinds, 3))
    with open(path, "w") as fh:
        fh.write("#VRML V2.0 utf8\n")
        if layout == "use":
            defined = set()
            for i in range(n):
                k = kind[i]
                fh.write(f"Transform {{ translation {centers[i, 0]:.6e} {centers[i, 1]:.6e} {centers[i, 2]:.6e} "
                         f"rotation 0 0 1 0.5 scale 0.3 0.3 0.3 children [\n")
                if k in defined:
                    fh.write(f"  USE M{k} ] }}\n")
                    continue
                defined.add(k)
                fh.write(f"  DEF M{k} Shape {{ appearance Appearance {{ material Material {{ diffuseColor "
                         f"{colour[k, 0]:.4f} {colour[k, 1]:.4f} {colour[k, 2]:.4f} }} }}\n"
                         "  geometry IndexedFaceSet { solid FALSE coord Coordinate { point [\n")
                fh.writelines(f"{p[0]:.6e} {p[1]:.6e} {p[2]:.6e},\n" for p in pts)
                fh.write("] } coordIndex [\n")
                fh.writelines(" ".join(map(str, f)) + " -1\n" for f in faces)
                fh.write("] } } ] }\n")
        else:
            nv = len(pts)
            for k in range(kinds):
                ids = np.flatnonzero(kind == k)
                fh.write(f"Shape {{ appearance Appearance {{ material Material {{ diffuseColor "
                         f"{colour[k, 0]:.4f} {colour[k, 1]:.4f} {colour[k, 2]:.4f} }} }}\n"
                         "geometry IndexedFaceSet { solid FALSE coord Coordinate { point [\n")
                for i in ids:
                    w = centers[i] + 0.3 * pts
                    fh.writelines(f"{p[0]:.6e} {p[1]:.6e} {p[2]:.6e},\n" for p in w)
                fh.write("] } coordIndex [\n")
                for j in range(len(ids)):
                    fh.writelines(" ".join(str(v + j * nv) for v in f) + " -1\n" for f in faces)
                fh.write("] } }\n")


def import_seconds(path: str) -> float:
    import vtk
    ren = vtk.vtkRenderer()
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.AddRenderer(ren)
    imp = vtk.vtkVRMLImporter()
    imp.SetFileName(path)
    imp.SetRenderWindow(win)
    t = time.perf_counter()
    imp.Update()
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="250,500,1000,2000,4000")
    ap.add_argument("--tess", type=int, default=8)
    ap.add_argument("--layouts", default="use,flat")
    ap.add_argument("--limit", type=float, default=60.0)
    args = ap.parse_args()
    print("layout,particles,seconds,file_mb")
    with tempfile.TemporaryDirectory() as tmp:
        for layout in args.layouts.split(","):
            for n in (int(x) for x in args.sizes.split(",")):
                path = os.path.join(tmp, f"{layout}-{n}.wrl")
                write(path, layout, n, args.tess)
                s = import_seconds(path)
                print(f"{layout},{n},{s:.2f},{os.path.getsize(path) / 1e6:.1f}", flush=True)
                os.unlink(path)
                if s > args.limit:
                    break


if __name__ == "__main__":
    main()
