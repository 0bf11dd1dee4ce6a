!> The model: what a run produces and `anm verify` and the Python package read. Stored in the
!> HDF5 model file, contract version 1 (DESIGN.md; user documentation in docs/model-file.md).
!>
!> Memory per particle: shape index, centre, rotation, scale, order, sieve (about 110 bytes) and
!> the shell thicknesses; never a copy of the surface.
!>
!> Usage:
!>     call write_model("out/model.h5", model, error)    ! atomic: temporary name, then rename
!>     call read_model("out/model.h5", model, error)
module anm_io_model
   use, intrinsic :: iso_c_binding, only: c_char, c_int, c_null_char
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type, sh_from_rows, sh_to_rows
   use anm_io_hdf5, only: h5_file_type, h5_create, h5_open_read, h5_close, h5_group, h5_write, h5_write_attr, &
      & h5_read, h5_read_attr, h5_exists, h5_read_fixed_strings
   implicit none
   private

   public :: model_type, write_model, read_model, model_format_version

   !> Version of the model-file contract written.
   integer, parameter :: model_format_version = 1

   !> A packed model.
   type :: model_type
      !> Box edges (mm) and periodicity.
      real(wp) :: box(3) = 0.0_wp
      !> Periodic boundaries.
      logical :: periodic = .true.
      !> Shapes (full expansions as read or generated) and their names.
      type(sh_expansion_type), allocatable :: shapes(:)
      !> Shape names.
      character(len=256), allocatable :: shape_names(:)
      !> Number of particles.
      integer :: np = 0
      !> Per particle: shape index (1-based in memory, 0-based in the file), order, sieve (1-based).
      integer, allocatable :: shape(:), nmax(:), sieve(:)
      !> Per particle: centre (3, np) in mm, inside the box.
      real(wp), allocatable :: center(:, :)
      !> Per particle: rotation body->world (3, 3, np), world = R body.
      real(wp), allocatable :: rotation(:, :, :)
      !> Per particle: mm per shape unit.
      real(wp), allocatable :: scale(:)
      !> Per particle: cumulative shell thickness per layer (nshell, np), mm.
      real(wp), allocatable :: shell_thickness(:, :)
      !> Shell specification, per layer: cumulative thickness in `layer_unit` (nlayer).
      real(wp), allocatable :: layer_thickness(:)
      !> Shell specification: RGB colour (0..1) per layer (3, nlayer).
      real(wp), allocatable :: layer_colour(:, :)
      !> Shell specification: unit of layer_thickness ("mm" or "fraction") and placement mode
      !> ("exclude", "shell_overlap" or "overlap"); unallocated: no /shells group (older files).
      character(len=:), allocatable :: layer_unit, layer_mode
      !> Per sieve: width range, target and achieved fraction of the box, count.
      real(wp), allocatable :: min_width(:), max_width(:), target_fraction(:), achieved_fraction(:)
      !> Per sieve: number of particles.
      integer, allocatable :: count(:)
      !> Per sieve: shell volume fraction of the box (outermost layer minus particles), 0 without shells.
      real(wp), allocatable :: shell_fraction(:)
      !> Input namelist text and the resolved configuration.
      character(len=:), allocatable :: namelist, resolved
      !> Run attributes.
      integer(i8) :: seed = 0
      !> Threads used.
      integer :: threads = 1
      !> Wall time (s).
      real(wp) :: wall_time = 0.0_wp
      !> Placement attempts made.
      integer(i8) :: attempts = 0
      !> Program version.
      character(len=:), allocatable :: version
   end type model_type

   interface
      function c_rename(old, new) bind(c, name="rename") result(stat)
         import :: c_char, c_int
         character(kind=c_char), intent(in) :: old(*), new(*)
         integer(c_int) :: stat
      end function c_rename
   end interface

contains

   !> Write the model file atomically: to PATH.tmp, then rename to PATH.
   subroutine write_model(path, model, error)
      !> Model file name.
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(in) :: model
      !> Error naming file::dataset.
      type(error_type), allocatable, intent(out) :: error
      type(h5_file_type) :: f
      type(error_type), allocatable :: err2
      character(len=:), allocatable :: tmp
      real(wp), allocatable :: coeffs(:, :, :), rot(:, :, :)
      complex(wp), allocatable :: c(:, :)
      integer, allocatable :: nmax(:)
      integer :: ns, ncoef, s, n, m, k, p, nmx

      tmp = path//".tmp"
      call h5_create(f, tmp, error)
      if (allocated(error)) return
      call h5_write_attr(f, "/", "format", "anm-model", error)
      if (allocated(error)) goto 99
      call h5_write_attr(f, "/", "format_version", model_format_version, error)
      if (allocated(error)) goto 99
      call h5_group(f, "/box", error)
      if (allocated(error)) goto 99
      call h5_write(f, "/box/length", model%box, error)
      if (allocated(error)) goto 99
      call h5_write_attr(f, "/box", "periodic", merge(1, 0, model%periodic), error)
      if (allocated(error)) goto 99

      ns = size(model%shapes)
      nmx = 0
      do s = 1, ns
         nmx = max(nmx, model%shapes(s)%nmax)
      end do
      ncoef = (nmx + 1)**2
      allocate (coeffs(2, ncoef, ns), nmax(ns))
      coeffs = 0.0_wp
      do s = 1, ns
         nmax(s) = model%shapes(s)%nmax
         coeffs(:, :(nmax(s) + 1)**2, s) = sh_to_rows(model%shapes(s))
      end do
      call h5_group(f, "/shapes", error)
      if (allocated(error)) goto 99
      call h5_write(f, "/shapes/coeffs", coeffs, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/shapes/nmax", nmax, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/shapes/name", model%shape_names, error)
      if (allocated(error)) goto 99

      call h5_group(f, "/particles", error)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/shape", model%shape(:model%np) - 1, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/center", model%center(:, :model%np), error)
      if (allocated(error)) goto 99
      ! numpy reads (np, 3, 3) with R[p, i, j] = file(j, i, p) in Fortran order: store the transpose
      allocate (rot(3, 3, model%np))
      do p = 1, model%np
         rot(:, :, p) = transpose(model%rotation(:, :, p))
      end do
      call h5_write(f, "/particles/rotation", rot, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/scale", model%scale(:model%np), error)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/nmax", model%nmax(:model%np), error)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/sieve", model%sieve(:model%np) - 1, error)
      if (allocated(error)) goto 99
      if (allocated(model%shell_thickness)) then
         if (size(model%shell_thickness, 1) > 0) then
            call h5_write(f, "/particles/shell_thickness", model%shell_thickness(:, :model%np), error)
            if (allocated(error)) goto 99
         end if
      end if

      call h5_group(f, "/sieves", error)
      if (allocated(error)) goto 99
      call h5_write(f, "/sieves/min_width", model%min_width, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/sieves/max_width", model%max_width, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/sieves/target_fraction", model%target_fraction, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/sieves/achieved_fraction", model%achieved_fraction, error)
      if (allocated(error)) goto 99
      call h5_write(f, "/sieves/count", model%count, error)
      if (allocated(error)) goto 99
      if (allocated(model%shell_fraction)) then
         call h5_write(f, "/sieves/shell_fraction", model%shell_fraction, error)
         if (allocated(error)) goto 99
      end if

      if (allocated(model%layer_unit)) then
         call write_shells(f, model, error)
         if (allocated(error)) goto 99
      end if

      call h5_group(f, "/run", error)
      if (allocated(error)) goto 99
      call h5_write(f, "/run/namelist", model%namelist, error)
      if (allocated(error)) goto 99
      if (allocated(model%resolved)) then
         call h5_write(f, "/run/resolved_namelist", model%resolved, error)
         if (allocated(error)) goto 99
      end if
      call h5_write_attr(f, "/run", "seed", model%seed, error)
      if (allocated(error)) goto 99
      call h5_write_attr(f, "/run", "threads", model%threads, error)
      if (allocated(error)) goto 99
      call h5_write_attr(f, "/run", "program_version", model%version, error)
      if (allocated(error)) goto 99
      call h5_write_attr(f, "/run", "wall_time", model%wall_time, error)
      if (allocated(error)) goto 99
      call h5_write_attr(f, "/run", "attempts", real(model%attempts, wp), error)
      if (allocated(error)) goto 99
      call h5_close(f, error)
      if (allocated(error)) return
      if (c_rename(tmp//c_null_char, trim(path)//c_null_char) /= 0) then
         call fatal_error(error, path//": cannot rename "//tmp//" to the model file", error_code%io)
      end if
      return
99    call h5_close(f, err2)
   end subroutine write_model

   !> The shell specification as group /shells: attributes nlayer, unit, mode; datasets thickness
   !> (nlayer, in unit) and colour (nlayer x 3 as numpy reads it). docs/model-file.md.
   subroutine write_shells(f, model, error)
      type(h5_file_type), intent(in) :: f
      type(model_type), intent(in) :: model
      type(error_type), allocatable, intent(out) :: error
      integer :: nl
      nl = 0
      if (allocated(model%layer_thickness)) nl = size(model%layer_thickness)
      call h5_group(f, "/shells", error)
      if (allocated(error)) return
      call h5_write_attr(f, "/shells", "nlayer", nl, error)
      if (allocated(error)) return
      call h5_write_attr(f, "/shells", "unit", model%layer_unit, error)
      if (allocated(error)) return
      call h5_write_attr(f, "/shells", "mode", model%layer_mode, error)
      if (allocated(error)) return
      if (nl == 0) return
      call h5_write(f, "/shells/thickness", model%layer_thickness, error)
      if (allocated(error)) return
      call h5_write(f, "/shells/colour", model%layer_colour, error)
   end subroutine write_shells

   !> Read a model file (contract version 1). Errors name file::dataset.
   subroutine read_model(path, model, error)
      !> Model file.
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(out) :: model
      !> Error.
      type(error_type), allocatable, intent(out) :: error
      type(h5_file_type) :: f
      type(error_type), allocatable :: err2
      character(len=:), allocatable :: fmt
      real(wp), allocatable :: coeffs(:, :, :), rot(:, :, :), tmp1(:)
      integer, allocatable :: nmax(:), ivec(:)
      integer :: ver, per, s, p, ns

      call h5_open_read(f, path, error)
      if (allocated(error)) return
      call h5_read_attr(f, "/", "format", fmt, error)
      if (allocated(error)) goto 99
      if (trim(fmt) /= "anm-model") then
         call fatal_error(error, path//": not an Anm model file (format = '"//trim(fmt)//"')", error_code%format)
         goto 99
      end if
      call h5_read_attr(f, "/", "format_version", ver, error)
      if (allocated(error)) goto 99
      if (ver < 1 .or. ver > model_format_version) then
         call fatal_error(error, path//": unsupported format_version "//to_string(ver), error_code%format)
         goto 99
      end if
      call h5_read(f, "/box/length", tmp1, error)
      if (allocated(error)) goto 99
      if (size(tmp1) /= 3) then
         call fatal_error(error, path//"::/box/length: expected 3 values", error_code%format)
         goto 99
      end if
      model%box = tmp1
      call h5_read_attr(f, "/box", "periodic", per, error)
      if (allocated(error)) goto 99
      model%periodic = per /= 0
      call h5_read(f, "/shapes/coeffs", coeffs, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/shapes/nmax", nmax, error)
      if (allocated(error)) goto 99
      ns = size(nmax)
      allocate (model%shapes(ns))
      do s = 1, ns
         if (nmax(s) < 0 .or. (nmax(s) + 1)**2 > size(coeffs, 2)) then
            call fatal_error(error, path//"::/shapes/nmax: degree "//to_string(nmax(s))//" of shape " &
                             //to_string(s - 1)//" does not fit /shapes/coeffs", error_code%format)
            goto 99
         end if
         model%shapes(s) = sh_from_rows(coeffs(:, :, s), nmax(s))
      end do
      call h5_read_fixed_strings(f, "/shapes/name", model%shape_names, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/particles/shape", ivec, error)
      if (allocated(error)) goto 99
      model%np = size(ivec)
      model%shape = ivec + 1
      if (any(model%shape < 1 .or. model%shape > ns)) then
         call fatal_error(error, path//"::/particles/shape: index out of range", error_code%format)
         goto 99
      end if
      call h5_read(f, "/particles/center", model%center, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/particles/rotation", rot, error)
      if (allocated(error)) goto 99
      allocate (model%rotation(3, 3, model%np))
      do p = 1, model%np
         model%rotation(:, :, p) = transpose(rot(:, :, p))
      end do
      call h5_read(f, "/particles/scale", model%scale, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/particles/nmax", model%nmax, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/particles/sieve", ivec, error)
      if (allocated(error)) goto 99
      model%sieve = ivec + 1
      if (h5_exists(f, "/particles/shell_thickness")) then
         call h5_read(f, "/particles/shell_thickness", model%shell_thickness, error)
         if (allocated(error)) goto 99
      else
         allocate (model%shell_thickness(0, model%np))
      end if
      if (h5_exists(f, "/shells")) then
         call read_shells(f, model, error)
         if (allocated(error)) goto 99
      end if
      call h5_read(f, "/sieves/min_width", model%min_width, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/sieves/max_width", model%max_width, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/sieves/target_fraction", model%target_fraction, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/sieves/achieved_fraction", model%achieved_fraction, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/sieves/count", model%count, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/run/namelist", model%namelist, error)
      if (allocated(error)) goto 99
      if (size(model%center, 1) /= 3 .or. size(model%center, 2) /= model%np .or. size(model%scale) /= model%np) then
         call fatal_error(error, path//"::/particles: datasets of inconsistent length", error_code%format)
         goto 99
      end if
      call h5_close(f, error)
      return
99    call h5_close(f, err2)
   end subroutine read_model

   !> Read the optional group /shells (files written before it existed have none).
   subroutine read_shells(f, model, error)
      type(h5_file_type), intent(in) :: f
      type(model_type), intent(inout) :: model
      type(error_type), allocatable, intent(out) :: error
      integer :: nl
      call h5_read_attr(f, "/shells", "nlayer", nl, error)
      if (allocated(error)) return
      call h5_read_attr(f, "/shells", "unit", model%layer_unit, error)
      if (allocated(error)) return
      call h5_read_attr(f, "/shells", "mode", model%layer_mode, error)
      if (allocated(error)) return
      if (nl <= 0) then
         allocate (model%layer_thickness(0), model%layer_colour(3, 0))
         return
      end if
      call h5_read(f, "/shells/thickness", model%layer_thickness, error)
      if (allocated(error)) return
      call h5_read(f, "/shells/colour", model%layer_colour, error)
      if (allocated(error)) return
      if (size(model%layer_thickness) /= nl .or. size(model%layer_colour, 1) /= 3 &
          .or. size(model%layer_colour, 2) /= nl) then
         call fatal_error(error, f%name//"::/shells: thickness and colour do not match nlayer = "//to_string(nl), &
                          error_code%format)
      end if
   end subroutine read_shells
end module anm_io_model
