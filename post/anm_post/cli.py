"""The `anm-post` command line (also `python -m anm_post`): a thin layer over the library."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from .errors import AnmPostError
from .output import OutputSet, check_array_suffix, figure_format, write_text
from .tables import read_geometry_table, psd_table, format_psd

EPILOG = """examples:
  anm-post table out/default.h5                       PSD table of a model (text; --format csv|markdown)
  anm-post table geom.txt --format markdown           geometry table written by `anm shape`
  anm-post slice out/default.h5 --axis z --position 10 --pixel 0.05 --png out/slice.png --labels out/slice.npz
  anm-post slice out/default.h5 --axis z --position 10 --pixel 0.05 --shells 0.02 --png out/itz.png
  anm-post slice out/default.h5 --center 10 10 10 --normal 1 1 0 --size 12 12 --pixel 0.04 --png out/oblique.png
  anm-post slice out/default.h5 --axis x --pixel 0.1 --density 0.1 --labels out/stack.h5   (stack, rho_s = 0.1)
  anm-post plot next.csv -o next.png                  plot of `anm study next|nbox ... --csv next.csv`
  anm-post rdf out/msand/model.h5 --density 1 --volume --csv g.csv --png g.png   wall effect g(t), slices and 3D
  anm-post convergence out/msand/model.h5 --densities 0.01,0.1,0.5,1 --csv conv.csv --png conv.png
  anm-post export out/default.h5 --format vtkhdf --output out/default.vtkhdf   surfaces + centres for ParaView
  anm-post voxels out/default.h5 --voxel 0.1 --output out/default-voxels.h5   labelled 3D image (also raw, vcctl)
  anm-post law out/default.h5 --axis z --slabs 20 --gap-sieves 1 --png law.png   orientation, slab density, gaps
"""


def _floats(text: str, option: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise AnmPostError(f"{option}: expected comma-separated numbers, got {text!r}") from None


def _is_model(path: str) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(8) == b"\x89HDF\r\n\x1a\n"
    except OSError:
        return path.endswith((".h5", ".hdf5"))


def _cmd_table(args: argparse.Namespace) -> int:
    if _is_model(args.table):
        from .model import read_model
        model = read_model(args.table)
        rows = psd_table(model)
        fmt = "text" if args.format == "summary" else args.format
        sys.stdout.write(format_psd(rows, fmt))
        if args.csv:
            write_text(args.csv, format_psd(rows, "csv"), "--csv")
        return 0
    table = read_geometry_table(args.table)
    if args.csv:
        write_text(args.csv, table.to_csv(), "--csv")
    if args.format == "csv":
        sys.stdout.write(table.to_csv())
    elif args.format in ("markdown", "text"):
        cols = ["volume", "surf._area", "length(mm)", "width(mm)", "thick(mm)", "L/T", "W/T"]
        sys.stdout.write(table.to_markdown([c for c in cols if c in table.columns]))
    summary = table.summary()
    print(f"{len(table)} particles; " + "; ".join(f"mean {k} = {m:.3f} +- {s:.3f}" for k, (m, s) in summary.items()))
    return 0


def _plane_from_args(args: argparse.Namespace, model):
    from .slicing import Plane, axis_plane

    if args.center is not None or args.normal is not None:
        if args.center is None or args.normal is None or args.size is None:
            raise AnmPostError("--center, --normal and --size go together (an oblique slice)")
        if not np.all(np.isfinite(np.asarray(args.center, float))):
            raise AnmPostError(f"--center: must be a finite point, got {args.center}")
        n = np.asarray(args.normal, float)
        if not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise AnmPostError(f"--normal: must be a non-zero vector, got {args.normal}")
        n /= np.linalg.norm(n)
        a = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = np.cross(a, n)
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        w, h = args.size
        origin = np.asarray(args.center, float) - 0.5 * w * u - 0.5 * h * v
        return Plane(tuple(origin), tuple(u), tuple(v), (w, h), args.pixel)
    if args.position is None:
        raise AnmPostError("--position: required with --axis for a single slice (or give --density for a stack)")
    return axis_plane(model, args.axis, args.position, args.pixel)


def _shell_spec(args: argparse.Namespace, model, ids):
    """The one meaning of --shells: the shell layers. Absent or `model`: the layers stored in the
    model (group /shells; none for files that have no such group); `none`: no shells;
    T1[,T2..]: these cumulative thicknesses in --shell-unit."""
    from .slicing import ShellSpec
    choice = "model" if args.shells is None else args.shells.strip()
    if choice.lower() == "none":
        return None
    if choice.lower() == "model":
        try:
            spec = ShellSpec.stored(model, particles=ids)
        except AnmPostError as exc:
            raise AnmPostError(f"--shells: {exc}") from None
        if spec is None and args.shells is not None:
            raise AnmPostError(f"--shells: {model.path} stores no shell layers (no /shells group or nlayer = 0); "
                               "give the thicknesses, e.g. --shells 0.02")
        return spec
    try:
        return ShellSpec(_floats(choice, "--shells"), unit=args.shell_unit, particles=ids)
    except AnmPostError as exc:
        raise AnmPostError(f"--shells/--shell-particles: {exc}") from None


def _preparing(command: str, model) -> None:
    """A first progress line for big models, whose preparation (forms, shells, cell list) takes
    seconds before the first slice: so that a log shows the command is working."""
    if model.n_particles >= 10_000:
        print(f"anm-post {command}: preparing the shapes of {model.n_particles} particles", file=sys.stderr,
              flush=True)


def _cmd_slice(args: argparse.Namespace) -> int:
    from .model import read_model
    from .slicing import Slicer
    from .images import save_slice_png

    if not (args.pixel > 0 and np.isfinite(args.pixel)):
        raise AnmPostError(f"--pixel: must be a positive size in mm, got {args.pixel}")
    model = read_model(args.model)
    ids = None
    if args.shell_particles:
        try:
            ids = tuple(int(x) for x in args.shell_particles.split(","))
        except ValueError:
            raise AnmPostError(f"--shell-particles: expected comma-separated ids, got {args.shell_particles!r}") \
                from None
    shells = _shell_spec(args, model, ids)
    nlayer = 0 if shells is None else len(shells.thickness)
    _preparing("slice", model)
    try:
        slicer = Slicer(model, shells)
    except AnmPostError as exc:
        raise AnmPostError(f"--shell-particles: {exc}") from None
    if args.density is not None:
        _check_stack_memory(args, model)
        from .slicing import stack_positions
        from .progress import stderr_progress
        try:
            k = "xyz".index(args.axis) if args.axis in ("x", "y", "z") else int(args.axis)
            total = len(stack_positions(0.0, float(model.box[k]), args.pixel, args.density))
            report = stderr_progress("slices")
            results = []
            for r in slicer.stack(args.axis, args.pixel, args.density):
                results.append(r)
                report(len(results), total)
        except AnmPostError as exc:
            raise AnmPostError(f"--density: {exc}") from None
        k = "xyz".index(args.axis)
        print("slice,position_mm,particle_fraction" + "".join(f",layer{j}_fraction" for j in range(1, nlayer + 1)))
        for i, r in enumerate(results):
            print(f"{i},{r.plane.origin[k]:.6g},{r.particle_fraction:.6f}"
                  + "".join(f",{f:.6f}" for f in r.layer_fractions(nlayer)))
        mean = np.mean([r.particle_fraction for r in results])
        print(f"# {len(results)} slices (rho_s = {args.density}), mean particle area fraction {mean:.4f}",
              file=sys.stderr)
        if args.labels:
            _save_stack(results, args.labels)
        if args.png:
            save_slice_png(results[len(results) // 2], model, args.png, nlayer)
        return 0
    try:
        plane = _plane_from_args(args, model)
    except AnmPostError as exc:
        raise AnmPostError(str(exc) if str(exc).startswith("--") else f"--position/--size/--pixel: {exc}") from None
    _check_slice_memory(plane, 1, 1, args)
    result = slicer.slice(plane)
    print(f"{model.path}: slice {result.particle.shape[1]} x {result.particle.shape[0]} pixels of {plane.pixel:g} mm; "
          f"particle area fraction {result.particle_fraction:.4f}"
          + "".join(f"; layer {j} {f:.4f}" for j, f in enumerate(result.layer_fractions(nlayer), start=1)))
    if args.labels:
        result.save(args.labels)
    if args.png:
        save_slice_png(result, model, args.png, nlayer)
    return 0


def _check_slice_memory(plane, kept: int, chunk: int, args: argparse.Namespace, option: str = "--pixel") -> None:
    """Refuse up front slices whose label arrays would not fit in memory (anm_post.resources)."""
    from .resources import check_memory, slice_memory
    nv, nu = plane.shape
    need = slice_memory(nu * nv, kept, chunk, png=bool(getattr(args, "png", None)),
                        labels=bool(getattr(args, "labels", None)))
    what = f"{kept} slice{'s' if kept > 1 else ''} of {nu} x {nv} pixels"
    check_memory(need, what, option)


def _check_stack_memory(args: argparse.Namespace, model) -> None:
    from .slicing import axis_plane, stack_positions
    k = "xyz".index(args.axis)
    try:
        n = len(stack_positions(0.0, float(model.box[k]), args.pixel, args.density))
        plane = axis_plane(model, args.axis, 0.0, args.pixel)
    except AnmPostError as exc:
        raise AnmPostError(f"--density/--pixel: {exc}") from None
    _check_slice_memory(plane, n, min(n, 8), args, "--pixel/--density")


def _save_stack(results, path: str) -> None:
    p = Path(path)
    arrays = {k: np.stack([getattr(r, k) for r in results]) for k in ("particle", "layer", "owner", "sieve")}
    origins = np.array([r.plane.origin for r in results])
    from .output import save_arrays
    save_arrays(p, dict(origin=origins, **arrays), dict(pixel=results[0].plane.pixel), "anm-slice-stack",
                "--labels")


def _cmd_plot(args: argparse.Namespace) -> int:
    from .plots import plot_study
    plot_study(args.csv, args.output)
    print(_final_path(args, "output"))
    return 0


def _cmd_law(args: argparse.Namespace) -> int:
    from .model import read_model
    from . import law

    if args.slabs < 1:
        raise AnmPostError(f"--slabs: must be at least 1, got {args.slabs}")
    if not (args.reach >= 0 and np.isfinite(args.reach)):
        raise AnmPostError(f"--reach: must be a distance >= 0 in mm, got {args.reach}")
    model = read_model(args.model)
    gap_sieves = None
    if args.gap_sieves.strip().lower() == "none":
        gap_sieves = []
    elif args.gap_sieves.strip().lower() != "all":
        try:
            gap_sieves = [int(x) - 1 for x in args.gap_sieves.split(",") if x.strip()]
        except ValueError:
            raise AnmPostError(f"--gap-sieves: expected 1-based sieve numbers, all or none, got {args.gap_sieves!r}") \
                from None
        bad = [s + 1 for s in gap_sieves if not 0 <= s < model.n_sieves]
        if bad:
            raise AnmPostError(f"--gap-sieves: {model.path} has sieves 1..{model.n_sieves}, not {bad[0]}")
    _preparing("law", model)
    orient = law.orientations(model)
    vols = law.particle_volumes(model)
    slabs = law.slab_profiles(model, "xyz".index(args.axis), args.slabs, volumes=vols)
    gaps = None if gap_sieves == [] else law.centre_line_gaps(model, gap_sieves, reach=args.reach)
    sys.stdout.write(law.format_report(model, orient, slabs, gaps, gap_sieves))
    if args.csv:
        write_text(args.csv, law.profiles_csv(slabs), "--csv")
    if args.png:
        law.plot_law(slabs, gaps, args.png)
    return 0


def _triple(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None


def _rdf_spec(args: argparse.Namespace):
    from .walleffect import RdfSpec
    sieves = None
    if args.sieves:
        try:
            sieves = tuple(int(x) for x in args.sieves.split(",") if x.strip())
        except ValueError:
            raise AnmPostError(f"--sieves: expected comma-separated 0-based sieve numbers, got {args.sieves!r}") \
                from None
    try:
        return RdfSpec(particle=args.particle, width=args.width, length=args.length, n_shells=args.bins,
                       t_min=args.t_min, t_max=args.t_max,
                       unit=args.unit, axis=args.axis, pixel=args.pixel, density=getattr(args, "density", 1.0),
                       small_sieves=sieves, small_below=args.below, phi_b=args.phi_b)
    except AnmPostError as exc:
        text = str(exc)
        option = next((o for key, o in (("number of shells", "--bins"), ("shell distances", "--t-min/--t-max"),
                                        ("pixel", "--pixel"), ("density", "--density"), ("bulk", "--phi-b"),
                                        ("id, width and length", "--particle/--width/--length"),
                                        ("particle width", "--width"), ("particle length", "--length"))
                       if key in text), "options")
        raise AnmPostError(f"{option}: {text}") from None


def _check_particle(args: argparse.Namespace, model) -> None:
    if args.particle is not None and not 0 <= args.particle < model.n_particles:
        raise AnmPostError(f"--particle: {args.particle} is not a particle id of {model.path} "
                           f"(0..{model.n_particles - 1})")


def _no_shells_option(args: argparse.Namespace) -> None:
    if getattr(args, "shells", None) is not None:
        raise AnmPostError("--shells: means the shell layers (slice, sweep); the number of distance shells of "
                           "g(t) is --bins K")


def _cmd_rdf(args: argparse.Namespace) -> int:
    from .model import read_model
    from .walleffect import plot_rdf, prepare, rdf, volume_fractions
    _no_shells_option(args)
    spec = _rdf_spec(args)
    model = read_model(args.model)
    _check_particle(args, model)
    if args.spacing is not None and not args.spacing > 0:
        raise AnmPostError(f"--spacing: must be positive, got {args.spacing}")
    if args.replicates < 2:
        raise AnmPostError(f"--replicates: at least 2 are needed for a standard error, got {args.replicates}")
    if args.seed < 0:
        raise AnmPostError(f"--seed: must be >= 0, got {args.seed}")
    from .progress import stderr_progress
    _preparing("rdf", model)
    st = prepare(model, spec)
    _check_rdf_memory(st, spec, [spec.density], args)
    res = rdf(model, spec, setup=st, progress=stderr_progress("g(t) slices"))
    vol = volume_fractions(model, spec, spacing=args.spacing, replicates=args.replicates, seed=args.seed,
                           setup=st) if args.volume else None
    print(f"particle {res.particle}: length {res.length:.4g} mm, phi_B {res.phi_b:.4f} (small sieves "
          f"{','.join(map(str, res.small_sieves))}), {len(res.positions)} slices, {res.seconds:.1f} s"
          + (f"; 3D: {vol.replicates} replicates of {vol.n_points // vol.replicates} points (spacing "
             f"{vol.spacing:g} mm), {vol.seconds:.1f} s" if vol else ""), file=sys.stderr)
    out = ["layer,t_inner_mm,t_outer_mm,g,g_sd,g_se" + (",g_3d,g_3d_se,diff_per_se" if vol else "")]
    for k in range(len(res.g)):
        line = f"{k + 1},{res.t_inner[k]:.4f},{res.t_outer[k]:.4f},{res.g[k]:.4f},{res.g_sd[k]:.4f},{res.g_se[k]:.4f}"
        if vol:
            g3 = vol.phi[k] / res.phi_b
            line += f",{g3:.4f},{vol.phi_se[k] / res.phi_b:.4f},{(res.g[k] - g3) / res.g_se[k]:.2f}"
        out.append(line)
    print("\n".join(out))
    if args.csv:
        res.to_csv(args.csv, vol)
    if args.png:
        plot_rdf(res, args.png, vol)
    return 0


def _check_rdf_memory(st, spec, densities, args: argparse.Namespace) -> None:
    """Refuse up front RDF slices that would not fit in memory (16 slices labelled at once)."""
    from .resources import check_memory, slice_memory
    from .slicing import n_max
    k = "xyz".index(spec.axis)
    iu, iv = [d for d in range(3) if d != k]
    ext = np.asarray(st.hi, float) - np.asarray(st.lo, float)
    nu, nv = (max(1, round(float(ext[d]) / spec.pixel)) for d in (iu, iv))
    n = max(1, int(round(max(densities) * n_max(float(ext[k]), spec.pixel))))
    need = slice_memory(nu * nv, 1, min(n, 16), png=False, labels=False)
    check_memory(need, f"{n} slices of {nu} x {nv} pixels (16 at a time)", "--pixel")


def _cmd_convergence(args: argparse.Namespace) -> int:
    from .model import read_model
    from .walleffect import convergence, plot_convergence
    _no_shells_option(args)
    spec = _rdf_spec(args)
    dens = _floats(args.densities, "--densities")
    layers = [int(x) for x in _floats(args.layers, "--layers")] if args.layers else None
    model = read_model(args.model)
    _check_particle(args, model)
    from .walleffect import prepare
    if not dens or not all(0 < d <= 1 for d in dens):
        raise AnmPostError(f"--densities: slice densities must be in (0, 1], got {args.densities!r}")
    if layers is not None and not all(1 <= k <= spec.n_shells for k in layers):
        raise AnmPostError(f"--layers: 1-based layers must be in 1..{spec.n_shells} (--bins), got {args.layers!r}")
    from .progress import stderr_progress
    _preparing("convergence", model)
    st = prepare(model, spec)
    _check_rdf_memory(st, spec, dens, args)
    conv = convergence(model, spec, dens, setup=st, progress=stderr_progress("g(t) slices"))
    print(f"{sum(len(r.positions) for r in conv.results)} slices in {conv.results[0].seconds:.1f} s",
          file=sys.stderr)
    print("density,n_slices," + ",".join(f"g{k + 1},sd{k + 1}" for k in range(len(conv.results[0].g))))
    for r in conv.results:
        print(f"{r.density:g},{len(r.positions)}," + ",".join(f"{g:.4f},{s:.4f}" for g, s in zip(r.g, r.g_sd)))
    if args.csv:
        conv.to_csv(args.csv)
    if args.png:
        plot_convergence(conv, args.png, layers)
    if args.rdf_png:
        from .walleffect import plot_rdf
        plot_rdf(conv.results[-1], args.rdf_png)
    return 0


def _cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import collect, plot_sweep, sweep_markdown
    runs = []
    for item in args.runs:
        value, sep, path = item.partition("=")
        try:
            runs.append((float(value), path))
        except ValueError:
            raise AnmPostError(f"run {item!r}: expected VALUE=SUMMARY.csv") from None
        if not sep:
            raise AnmPostError(f"run {item!r}: expected VALUE=SUMMARY.csv")
    if not np.isfinite(args.scale) or args.scale == 0:
        raise AnmPostError(f"--scale: must be a finite non-zero number, got {args.scale}")
    rows = collect(runs)
    choice = "auto" if args.shells is None else args.shells.strip().lower()
    if choice not in ("auto", "model", "none"):
        raise AnmPostError(f"--shells: sweep shows the runs' own shells: use --shells (or --shells model) to add the "
                           f"shell fraction panel, --shells none to leave it out; got {args.shells!r}")
    show_shells = choice == "model" or (choice == "auto" and any(r.shell_fraction > 0 for r in rows))
    text = sweep_markdown(rows, args.label, args.scale)
    sys.stdout.write(text)
    if args.markdown:
        write_text(args.markdown, text, "--markdown")
    if args.png:
        plot_sweep(rows, args.label, args.png, args.scale, shells=show_shells)
    return 0


# -- export and voxels (issue 17, items 2 and 3): self-contained, each writes its own outputs -----

def _own_shells(args: argparse.Namespace):
    """ShellSpec of --shells/--shell-unit/--shell-particles of export and voxels (None without)."""
    from .slicing import ShellSpec
    if not args.shells:
        return None
    ids = None
    if args.shell_particles:
        try:
            ids = tuple(int(x) for x in args.shell_particles.split(","))
        except ValueError:
            raise AnmPostError(f"--shell-particles: expected comma-separated ids, got {args.shell_particles!r}") \
                from None
    try:
        return ShellSpec(_floats(args.shells, "--shells"), unit=args.shell_unit, particles=ids)
    except AnmPostError as exc:
        raise AnmPostError(f"--shells/--shell-particles: {exc}") from None


def _own_output(args: argparse.Namespace, outputs, path: str, option: str = "--output") -> Path:
    """Check an output of export/voxels up front (anm_post.output) and refuse the model file."""
    out = outputs.add(path, option)
    model = Path(args.model)
    if out.exists() and model.exists() and os.path.samefile(out, model):
        raise AnmPostError(f"{out}: {option} would overwrite an input file of this command")
    return out


def _cmd_export(args: argparse.Namespace) -> int:
    from .export import FORMATS, estimate_bytes, surface_mesh, write_mesh
    from .model import read_model
    from .output import OutputSet
    from .resources import check_memory
    from .progress import stderr_progress

    fmt = args.format or next((f for f, suf in FORMATS.items() if args.out_file.endswith(suf)), None)
    if fmt is None:
        raise AnmPostError(f"{args.out_file}: --format not given and the suffix is not .vtu, .vtp or .vtkhdf")
    tess = [int(x) for x in _floats(args.tessellation, "--tessellation")] if args.tessellation else None
    with OutputSet() as outputs:
        out = _own_output(args, outputs, args.out_file)
        model = read_model(args.model)
        shells = _own_shells(args)
        from .export import default_tessellation
        t = tess or default_tessellation(model.n_sieves)
        if len(t) not in (1, model.n_sieves) or min(t) < 2:
            raise AnmPostError(f"--tessellation: one value >= 2 per sieve ({model.n_sieves}) or one for all, got {t}")
        t = t * model.n_sieves if len(t) == 1 else t
        check_memory(estimate_bytes(model, t, 0 if shells is None else len(shells.thickness)),
                     f"surfaces of {model.n_particles} particles at tessellation {','.join(map(str, t))}",
                     "--tessellation")
        try:
            mesh = surface_mesh(model, t, shells, progress=stderr_progress("surfaces"))
        except AnmPostError as exc:
            raise AnmPostError(f"--shells/--tessellation: {exc}") from None
        write_mesh(mesh, outputs.stage(out, "--output"), fmt)
    print(f"{out}: {fmt}, {mesh.n_particles} particles, {mesh.n_surfaces} surfaces, {len(mesh.points)} points, "
          f"{mesh.n_cells} cells (tessellation {','.join(map(str, t))})")
    return 0


#: Suffix -> voxel output format.
VOXEL_SUFFIXES = {".h5": "h5", ".hdf5": "h5", ".raw": "raw", ".img": "vcctl", ".vcctl": "vcctl"}


def _cmd_voxels(args: argparse.Namespace) -> int:
    from .model import read_model
    from .output import OutputSet
    from .resources import check_memory
    from .voxels import (default_chunk, grid_shape, memory_bytes, raw_header, save_h5, save_raw, save_vcctl,
                         voxelize)
    from .progress import stderr_progress

    fmt = args.format or VOXEL_SUFFIXES.get(Path(args.out_file).suffix.lower())
    if fmt is None:
        raise AnmPostError(f"{args.out_file}: --format not given and the suffix is not .h5, .raw or .img")
    with OutputSet() as outputs:
        out = _own_output(args, outputs, args.out_file)
        header = _own_output(args, outputs, str(out) + ".txt", "--output (header)") if fmt == "raw" else None
        model = read_model(args.model)
        shells = _own_shells(args)
        shape = grid_shape(model, args.voxel)
        check_memory(memory_bytes(shape, default_chunk(shape)), f"a voxel image of {shape[0]} x {shape[1]} x "
                     f"{shape[2]} voxels", "--voxel")
        try:
            img = voxelize(model, args.voxel, shells, progress=stderr_progress("voxels"))
        except AnmPostError as exc:
            raise AnmPostError(f"--shells: {exc}") from None
        if fmt == "h5":
            save_h5(img, outputs.stage(out, "--output"), str(model.path))
        elif fmt == "raw":
            save_raw(img, outputs.stage(out, "--output"))
            with open(outputs.stage(header, "--output (header)"), "w", encoding="utf-8") as fh:
                fh.write(raw_header(img, out.name))
        else:
            save_vcctl(img, outputs.stage(out, "--output"))
    nx, ny, nz = img.shape
    print(f"{out}: {fmt}, {nx} x {ny} x {nz} voxels of {img.voxel:g} mm in {img.seconds:.1f} s"
          + (f" (header {header})" if header else ""))
    print("code,phase,volume_fraction")
    for c, (name, f) in enumerate(zip(img.codes, img.fractions())):
        print(f"{c},{name},{f:.6f}")
    return 0


def _own_shell_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--shells", metavar="T1[,T2..]",
                   help="grow shells: cumulative outer distances of the layers from the surface")
    p.add_argument("--shell-unit", choices=["fraction", "mm"], default="fraction",
                   help="unit of --shells: fraction of each particle's length (default) or mm")
    p.add_argument("--shell-particles", metavar="ID[,ID..]", help="grow shells only around these 0-based particles")


def _add_export_voxels(sub) -> None:
    p = sub.add_parser("export", help="particle surfaces and centres for ParaView/VTK (vtu, vtp, vtkhdf)",
                       description="Write every particle surface (latitude-longitude tessellation per sieve, as "
                                   "the VRML; triangles and quads) and, with --shells, every shell layer's outer "
                                   "surface, plus the particle centres as vertex cells, with cell fields "
                                   "particle_id, sieve, shape, layer (0 = particle) and kind (0 centre, 1 surface). "
                                   "docs/paraview.md.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", help="model file written by `anm run` (.h5)")
    p.add_argument("--output", dest="out_file", required=True, metavar="FILE", help="output file")
    p.add_argument("--format", choices=["vtu", "vtp", "vtkhdf"], help="default: from the suffix of FILE")
    p.add_argument("--tessellation", metavar="T[,T..]",
                   help="polar divisions per sieve (or one for all); default anm's VRML one (32 for the first "
                        "sieve, coarser after); use e.g. 6,6,3 for M_sand-sized models")
    _own_shell_options(p)
    p.set_defaults(func=_cmd_export)

    p = sub.add_parser("voxels", help="labelled 3D voxel image (HDF5, raw stack, VCCTL ASCII)",
                       description="Label every voxel centre of the box with a phase code (0 matrix, 1.. the "
                                   "sieves, then the shell layers) and the particle id, from the slicing kernel "
                                   "(stacked z slices). Formats: h5 (/labels, /particle_id, attributes voxel_size "
                                   "and codes), raw (uint8 x fastest, header FILE.txt), vcctl (VCCTL's ASCII "
                                   "image). Prints the volume fraction of every code. docs/paraview.md.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", help="model file written by `anm run` (.h5)")
    p.add_argument("--voxel", type=float, required=True, metavar="MM", help="voxel edge in mm")
    p.add_argument("--output", dest="out_file", required=True, metavar="FILE", help="output file")
    p.add_argument("--format", choices=["h5", "raw", "vcctl"], help="default: from the suffix (.h5, .raw, .img)")
    _own_shell_options(p)
    p.set_defaults(func=_cmd_voxels)


def _rdf_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", help="model file written by `anm run` (.h5)")
    p.add_argument("--particle", type=int, metavar="ID", help="0-based id of the RDF particle (default: the longest)")
    p.add_argument("--width", type=float, metavar="MM",
                   help="RDF particle: the one of nearest width (mm) outside the small sieves (the thesis: 9.997)")
    p.add_argument("--length", type=float, metavar="MM",
                   help="RDF particle: the one of nearest length (mm) outside the small sieves")
    p.add_argument("--bins", type=int, default=10, metavar="K", help="number of distance shells K of g(t) (default 10)")
    p.add_argument("--shells", nargs="?", const="model", help=argparse.SUPPRESS)
    p.add_argument("--t-min", type=float, default=0.005, metavar="T", help="innermost shell distance (default 0.005)")
    p.add_argument("--t-max", type=float, default=0.05, metavar="T", help="outermost shell distance (default 0.05)")
    p.add_argument("--unit", choices=["fraction", "mm"], default="fraction",
                   help="unit of --t-min/--t-max: fraction of the RDF particle's length (default) or mm")
    p.add_argument("--axis", choices=["x", "y", "z"], default="x", help="slice normal (default x, as the thesis)")
    p.add_argument("--pixel", type=float, default=0.05, metavar="MM", help="pixel size R_s (default 0.05 mm)")
    p.add_argument("--sieves", metavar="S[,S..]", help="0-based sieves of the small particles (default: the finest)")
    p.add_argument("--below", type=float, metavar="MM", help="small particles: every sieve of max width <= MM")
    p.add_argument("--phi-b", type=float, metavar="PHI", help="bulk fraction phi_B (default: Eq 3.6 from the model)")
    p.add_argument("--csv", metavar="FILE", help="write the table to FILE")
    p.add_argument("--png", metavar="FILE", help="write the plot to FILE")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of anm-post."""
    parser = argparse.ArgumentParser(
        prog="anm-post",
        description="Post-processing of Anm model files: tables, 2D slices (label images), plots of studies, "
                    "VTK exports for ParaView and labelled 3D voxel images.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    from . import __version__
    parser.add_argument("--version", action="version", version=f"anm-post {__version__}",
                        help="print the version (that of the anm program, fpm.toml) and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{table,slice,plot,rdf,convergence,sweep,export,voxels}")

    p = sub.add_parser("table", help="PSD table of a model file, or a geometry table of `anm shape`",
                       description="With a model file (.h5): the PSD table (per sieve: width range, target and "
                                   "achieved volume fraction, count). With a text file: the geometry table summary.")
    p.add_argument("table", help="model file (HDF5) or geometry table file")
    p.add_argument("--csv", metavar="FILE", help="also write the table as CSV to FILE")
    p.add_argument("--format", choices=["summary", "text", "csv", "markdown"], default="summary",
                   help="model: text (default) | csv | markdown; geometry table: summary line (default), "
                        "markdown/text table or csv")
    p.set_defaults(func=_cmd_table)

    p = sub.add_parser("slice", help="2D slice(s) of a model: label arrays and a PNG picture",
                       description="Label every pixel of a slice with the particle containing it or the shell "
                                   "layer (shells grown now around all or chosen particles). Axis slice: --axis "
                                   "and --position; oblique slice: --center, --normal, --size; stack of parallel "
                                   "axis slices over the box: --axis and --density (thesis rho_s, Eqs 3.3-3.4).",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", help="model file written by `anm run` (.h5)")
    p.add_argument("--pixel", type=float, required=True, metavar="MM", help="pixel size R_s in mm per pixel")
    p.add_argument("--axis", choices=["x", "y", "z"], default="z", help="normal axis of an axis slice (default z)")
    p.add_argument("--position", type=float, metavar="MM", help="position of the axis slice along --axis (mm)")
    p.add_argument("--center", type=_triple, nargs=3, metavar=("X", "Y", "Z"), help="oblique slice: centre (mm)")
    p.add_argument("--normal", type=_triple, nargs=3, metavar=("NX", "NY", "NZ"), help="oblique slice: normal")
    p.add_argument("--size", type=_triple, nargs=2, metavar=("W", "H"), help="oblique slice: width, height (mm)")
    p.add_argument("--density", type=float, metavar="RHO",
                   help="stack of parallel slices along --axis at slice density rho_s in (0, 1]; prints a CSV of "
                        "area fractions per slice")
    p.add_argument("--shells", nargs="?", const="model", metavar="model|none|T1[,T2..]",
                   help="shell layers of the slice: by default (or `model`) the layers stored in the model "
                        "(/shells, the engine's per-particle thicknesses); `none`: no shells; T1[,T2..]: grow "
                        "these cumulative outer distances from the surface instead")
    p.add_argument("--shell-unit", choices=["fraction", "mm"], default="fraction",
                   help="unit of explicit --shells values: fraction of each particle's length (default) or mm")
    p.add_argument("--shell-particles", metavar="ID[,ID..]", help="grow shells only around these 0-based particles")
    p.add_argument("--png", metavar="FILE", help="write the picture (with a legend) to FILE")
    p.add_argument("--labels", metavar="FILE", help="write the label arrays to FILE (.npz, .h5)")
    p.set_defaults(func=_cmd_slice)

    p = sub.add_parser("plot", help="plot a contact study CSV (`anm study next|nbox SHAPE --csv FILE`)")
    p.add_argument("csv", help="CSV with header next,v_box,v_box_certified or nbox,d_overlap")
    p.add_argument("-o", "--output", metavar="PNG", help="output picture (default: the CSV name with .png)")
    p.set_defaults(func=_cmd_plot)

    p = sub.add_parser("rdf", help="wall effect g(t) around one particle (thesis 3.4, Fig 3.8)",
                       description="g(t) = small-particle fraction in each shell layer around the RDF particle "
                                   "divided by the bulk fraction phi_B (thesis Eqs 3.6, 3.10, 3.11), from parallel "
                                   "slices across the particle; with --volume also the same fraction measured in "
                                   "the volume (stratified random points in the layers, no slices; standard error "
                                   "from independent replicates). Prints a CSV table; with --volume its last column "
                                   "is (g - g_3d) / g_se, g_se the slices' standard error.",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    _rdf_options(p)
    p.add_argument("--density", type=float, default=1.0, metavar="RHO", help="slice density rho_s (default 1)")
    p.add_argument("--volume", action="store_true", help="also the 3D value of every layer (no slices)")
    p.add_argument("--spacing", type=float, metavar="MM",
                   help="cell size of the stratified volume sample (default: --pixel)")
    p.add_argument("--replicates", type=int, default=8, metavar="R",
                   help="independent volume samples for the standard error of the 3D value (default 8)")
    p.add_argument("--seed", type=int, default=1, help="seed of the volume samples (default 1)")
    p.set_defaults(func=_cmd_rdf)

    p = sub.add_parser("convergence", help="g(t) and its spread against the slice density (thesis Figs 3.9, 3.10)",
                       description="g(t) at several slice densities rho_s and the standard deviation of the "
                                   "per-slice values against rho_s for chosen layers (thesis Figs 3.9-3.13).",
                       epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    _rdf_options(p)
    p.add_argument("--densities", default="0.01,0.05,0.1,0.25,0.5,1", metavar="R1,R2..",
                   help="slice densities (default 0.01,0.05,0.1,0.25,0.5,1)")
    p.add_argument("--layers", metavar="K1,K2..", help="1-based layers of the s.d. panel (default: 4 spread layers)")
    p.add_argument("--rdf-png", metavar="FILE", help="also the bar plot of g(t) (Fig 3.8) at the highest density")
    p.set_defaults(func=_cmd_convergence)

    p = sub.add_parser("law", help="orientation, centre density and gap statistics of a model (docs/dense.md)",
                       description="The statistical law of a packing: eigenvalues of the orientation tensor of "
                                   "the particles' long axes per sieve (1/3 each for isotropy, with the standard "
                                   "error of an isotropic sample), the centre density of each sieve in slabs "
                                   "across the box (1 = homogeneous; the wall effect of a mould shows at the "
                                   "ends), and the centre-line gaps between the particles of chosen sieves.")
    p.add_argument("model", help="model file (.h5)")
    p.add_argument("--axis", choices=["x", "y", "z"], default="z", help="axis of the slab profiles (default z)")
    p.add_argument("--slabs", type=int, default=20, metavar="N", help="number of slabs (default 20)")
    p.add_argument("--gap-sieves", default="1", metavar="K1,K2..|all|none",
                   help="1-based sieves whose pairs give the gap distribution (default 1, the coarsest)")
    p.add_argument("--reach", type=float, default=0.5, metavar="MM",
                   help="pairs whose bounding spheres are closer than this (default 0.5 mm)")
    p.add_argument("--csv", metavar="FILE", help="write the slab profiles as CSV")
    p.add_argument("--png", metavar="FILE", help="picture of the slab profiles and the gap histogram")
    p.set_defaults(func=_cmd_law)

    p = sub.add_parser("sweep", help="table and plot of a parameter sweep of `anm run` (thesis Tables 2.1-2.3)",
                       description="Collect model-summary.csv files of runs that differ in one parameter into a "
                                   "Markdown table (PD and count per sieve, totals, shell fraction) and a plot "
                                   "(thesis Figs 2.16, 2.17).")
    p.add_argument("runs", nargs="+", metavar="VALUE=SUMMARY.csv", help="swept value and the run's summary file")
    p.add_argument("--label", default="value", help="name of the swept parameter (axis and column title)")
    p.add_argument("--scale", type=float, default=1.0, help="multiply the values by this for display (e.g. 100)")
    p.add_argument("--markdown", metavar="FILE", help="write the table to FILE")
    p.add_argument("--png", metavar="FILE", help="write the plot to FILE")
    p.add_argument("--shells", nargs="?", const="model", metavar="model|none",
                   help="shell volume fraction panel (Fig 2.17): shown by default when the runs have shells; "
                        "`--shells` or `--shells model` always, `--shells none` never")
    p.set_defaults(func=_cmd_sweep)
    _add_export_voxels(sub)
    return parser


# -- the one place where outputs are checked and staged and errors become messages -------------

#: Output options of the subcommands: attribute -> option name (anm_post.output: checked up front,
#: written to temporary names, renamed together when the command succeeds).
OUTPUT_OPTIONS = {"csv": "--csv", "png": "--png", "labels": "--labels", "markdown": "--markdown",
                  "output": "-o", "rdf_png": "--rdf-png"}
#: Input arguments (attribute names) an output must not overwrite.
INPUT_ARGUMENTS = ("model", "table", "csv", "runs")
#: Options that name pictures (their suffix must be a format matplotlib writes).
PICTURE_OPTIONS = ("png", "output", "rdf_png")


def _inputs(args: argparse.Namespace) -> list[Path]:
    out = []
    for attr in INPUT_ARGUMENTS:
        value = getattr(args, attr, None)
        if attr == "csv" and args.command != "plot":
            continue
        for v in (value if isinstance(value, list) else [value]):
            if isinstance(v, str):
                out.append(Path(v.partition("=")[2] if attr == "runs" else v))
    return [p for p in out if p.exists()]


def _stage_outputs(args: argparse.Namespace, outputs: OutputSet) -> None:
    """Check every output option up front (folder writable, suffix known, not an input file, not
    given twice) and replace it by a temporary name of `outputs`; args._final maps it back."""
    if args.command == "plot" and args.output is None:
        args.output = str(Path(args.csv).with_suffix(".png"))
    inputs = _inputs(args)
    args._final = {}
    seen: dict[str, str] = {}
    for attr, option in OUTPUT_OPTIONS.items():
        value = getattr(args, attr, None)
        if value is None or (attr == "csv" and args.command == "plot"):
            continue
        path = outputs.add(value, option)
        key = os.path.realpath(path)
        if key in seen:
            raise AnmPostError(f"{path}: given to both {seen[key]} and {option}; one file per output")
        seen[key] = option
        for source in inputs:
            if path.exists() and os.path.samefile(path, source):
                raise AnmPostError(f"{path}: {option} would overwrite an input file of this command")
        if attr in PICTURE_OPTIONS:
            figure_format(path, option)
        if attr == "labels":
            check_array_suffix(path, option)
        args._final[attr] = path
        setattr(args, attr, str(outputs.stage(path, option)))


def _final_path(args: argparse.Namespace, attr: str) -> str:
    return str(getattr(args, "_final", {}).get(attr, getattr(args, attr)))


def _run(args: argparse.Namespace) -> int:
    """Run a subcommand: outputs staged and committed as a set, every known error turned into
    `anm-post: error: MESSAGE` on stderr and exit code 1 (never a traceback; with ANM_DEBUG=1 an
    unexpected error shows its traceback)."""
    debug = os.environ.get("ANM_DEBUG", "") not in ("", "0")
    staged: dict[str, str] = {}
    try:
        with OutputSet() as outputs:
            try:
                _stage_outputs(args, outputs)
                staged = {str(tmp): str(final) for tmp, final, _ in outputs._staged}
                return args.func(args)
            finally:
                sys.stdout.flush()
    except AnmPostError as exc:
        message, code = str(exc), 1
    except MemoryError:
        message, code = ("out of memory; use a larger --pixel, a smaller --density or fewer slices "
                         "(no output was written)"), 1
    except KeyboardInterrupt:
        message, code = "interrupted (no output was written)", 130
    except BrokenPipeError:
        # the reader of stdout went away (`anm-post ... | head`): stop quietly
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 1
    except OSError as exc:
        if debug:
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        message, code = f"{where}{exc.strerror or exc}", 1
    except Exception as exc:  # an internal error: a short message, the traceback only on request
        if debug:
            raise
        message, code = (f"internal error ({type(exc).__name__}: {exc}); please report it with the command "
                         "line (ANM_DEBUG=1 shows the traceback)"), 1
    for tmp, final in staged.items():
        message = message.replace(tmp, final)
    print(f"anm-post: error: {message}", file=sys.stderr, flush=True)
    return code


def _line_buffered() -> None:
    """Progress and result lines reach a log file as they are printed (not block-buffered)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(line_buffering=True)
        except (AttributeError, ValueError):  # replaced streams (tests) may not support it
            pass


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (1 with a message on bad input, 2 for usage errors)."""
    _line_buffered()
    parser = build_parser()
    args = parser.parse_args(argv)
    return _run(args)


if __name__ == "__main__":
    sys.exit(main())
