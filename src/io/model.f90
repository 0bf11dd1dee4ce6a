!> The model: what a run produces and `anm verify` and the Python package read. Stored in the
!> HDF5 model file, contract version 1 (docs/model-file.md; units, frames and conventions in docs/conventions.md).
!>
!> Memory per particle: shape index, centre, rotation, scale, order, sieve (about 110 bytes) and
!> the shell thicknesses; never a copy of the surface.
!>
!> Usage:
!>     call write_model("out/model.h5", model, error)    ! safe: temporary name, then rename
!>     call read_model("out/model.h5", model, error)
module anm_io_model
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_text, only: printable
   use anm_core_output, only: output_set_type
   use anm_sh_expansion, only: sh_expansion_type, sh_from_rows, sh_to_rows
   use anm_io_model_schema, only: model_schema
   use anm_io_hdf5, only: h5_file_type, h5_create, h5_open_read, h5_close, h5_group, h5_write, h5_write_attr, &
      & h5_read, h5_read_attr, h5_exists, h5_read_strings, h5_parallel_type
   implicit none
   private

   public :: model_type, write_model, write_model_file, read_model, validate_model, model_format_version, &
      & rotation_tolerance

   !> Version of the model-file contract written.
   integer, parameter :: model_format_version = 1

   !> Tolerance of the rotation check on reading: every entry of R^T R - I and det R - 1 within
   !> 1e-6 (float64 rotations written by Anm are orthonormal to about 1e-15; 1e-6 also accepts
   !> rotations stored in float32 by other writers).
   real(wp), parameter :: rotation_tolerance = 1.0e-6_wp

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
      !> The particles the per-particle arrays hold: all np (first = -1), or, in the MPI build with
      !> divided arrays, this process' block first+1 .. first+size(scale) of them.
      integer :: first = -1
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


contains

   !> Write the model file safely: to a temporary name in the same folder (unique per process),
   !> every HDF5 call and the close checked, then renamed to PATH; on error the temporary is removed
   !> and an earlier PATH is kept.
   subroutine write_model(path, model, error)
      !> Model file name.
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(in) :: model
      !> Error naming file::dataset.
      type(error_type), allocatable, intent(out) :: error
      type(output_set_type) :: set
      character(len=:), allocatable :: tmp
      call set%add(path, tmp)
      call write_model_file(tmp, model, error, shown=path)
      if (allocated(error)) then
         call set%discard()
         return
      end if
      call set%commit(error)
   end subroutine write_model

   !> Write the model file `path` directly (the caller chooses a temporary name: see write_model).
   !> Errors name `shown` (default: path) and the dataset. With `par` (the MPI build), every process
   !> calls it with the same model and name and the file is written collectively through parallel
   !> HDF5: each process writes a block of the /particles datasets, process 0 the rest; the layout
   !> and the content are those of the serial file. With divided arrays (`model%first` >= 0) each
   !> process' model holds only its block (the same blocks).
   subroutine write_model_file(path, model, error, shown, par)
      !> Model file name.
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(in) :: model
      !> Error naming file::dataset.
      type(error_type), allocatable, intent(out) :: error
      !> Name used in messages (the final name when writing a temporary).
      character(len=*), intent(in), optional :: shown
      !> Processes writing the file together (collective).
      class(h5_parallel_type), intent(in), optional :: par
      type(h5_file_type) :: f
      type(error_type), allocatable :: err2
      real(wp), allocatable :: coeffs(:, :, :), rot(:, :, :)
      complex(wp), allocatable :: c(:, :)
      integer, allocatable :: nmax(:)
      integer :: ns, ncoef, s, n, m, k, p, nmx, nh
      integer(i8) :: first, total

      call h5_create(f, path, error, par)
      if (allocated(error)) goto 98
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

      ! the particles held: all, or (divided arrays, written in parallel) this process' block
      nh = model%np
      if (model%first >= 0) nh = size(model%scale)
      first = model%first
      total = model%np
      call h5_group(f, "/particles", error)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/shape", model%shape(:nh) - 1, error, split=.true., offset=first, total=total)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/center", model%center(:, :nh), error, split=.true., offset=first, total=total)
      if (allocated(error)) goto 99
      ! numpy reads (np, 3, 3) with R[p, i, j] = file(j, i, p) in Fortran order: store the transpose
      allocate (rot(3, 3, nh))
      do p = 1, nh
         rot(:, :, p) = transpose(model%rotation(:, :, p))
      end do
      call h5_write(f, "/particles/rotation", rot, error, split=.true., offset=first, total=total)
      if (allocated(error)) goto 99
      ! the in-memory file and its copy on closing come on top of the model: free the copy now
      ! (72 bytes per particle; 0.7 GB at 10^7 particles)
      deallocate (rot)
      call h5_write(f, "/particles/scale", model%scale(:nh), error, split=.true., offset=first, total=total)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/nmax", model%nmax(:nh), error, split=.true., offset=first, total=total)
      if (allocated(error)) goto 99
      call h5_write(f, "/particles/sieve", model%sieve(:nh) - 1, error, split=.true., offset=first, total=total)
      if (allocated(error)) goto 99
      if (allocated(model%shell_thickness)) then
         if (size(model%shell_thickness, 1) > 0) then
            call h5_write(f, "/particles/shell_thickness", model%shell_thickness(:, :nh), error, split=.true., &
                          offset=first, total=total)
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
      call h5_write_attr(f, "/run", "attempts", model%attempts, error)
      if (allocated(error)) goto 99
      call write_schema_attributes(f, error)
      if (allocated(error)) goto 99
      call h5_close(f, error)
      goto 98
99    call h5_close(f, err2)
98    if (allocated(error) .and. present(shown)) then
         ! name the final file, not the temporary
         if (index(error%message, path) == 1) error%message = shown//error%message(len(path) + 1:)
      end if
   end subroutine write_model_file

   !> The attributes `units` and `description` of every group and dataset written, from the one
   !> table anm_io_model_schema (docs/model-file.md lists the same rows).
   subroutine write_schema_attributes(f, error)
      type(h5_file_type), intent(in) :: f
      type(error_type), allocatable, intent(out) :: error
      integer :: k
      do k = 1, size(model_schema)
         associate (e => model_schema(k))
            if (trim(e%path) /= "/") then
               if (.not. h5_exists(f, trim(e%path))) cycle
            end if
            call h5_write_attr(f, trim(e%path), "units", trim(e%units), error)
            if (allocated(error)) return
            call h5_write_attr(f, trim(e%path), "description", trim(e%description), error)
            if (allocated(error)) return
         end associate
      end do
   end subroutine write_schema_attributes

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
      integer :: ver, per, s, p, ns, k

      call h5_open_read(f, path, error)
      if (allocated(error)) return
      call h5_read_attr(f, "/", "format", fmt, error)
      if (allocated(error)) goto 99
      if (trim(fmt) /= "anm-model") then
         call fatal_error(error, path//": not an Anm model file (format = '"//printable(trim(fmt))//"')", &
                          error_code%format)
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
      if (size(coeffs, 1) /= 2 .or. size(coeffs, 3) /= ns) then
         call fatal_error(error, path//"::/shapes/coeffs: expected shape ("//to_string(ns)//", ncoef, 2) for " &
                          //to_string(ns)//" shapes in /shapes/nmax", error_code%format)
         goto 99
      end if
      do s = 1, ns
         do k = 1, size(coeffs, 2)
            if (.not. all(finite(coeffs(:, k, s)))) then
               call fatal_error(error, path//"::/shapes/coeffs: shape "//to_string(s - 1)//", coefficient " &
                                //to_string(k - 1)//" is not a finite number", error_code%format)
               goto 99
            end if
         end do
         if (.not. (coeffs(1, 1, s) > 0.0_wp)) then
            call fatal_error(error, path//"::/shapes/coeffs: shape "//to_string(s - 1)//" has a_00 = " &
                             //to_string(coeffs(1, 1, s))//" (must be > 0: the mean radius)", error_code%format)
            goto 99
         end if
      end do
      allocate (model%shapes(ns))
      do s = 1, ns
         if (nmax(s) < 0 .or. (nmax(s) + 1)**2 > size(coeffs, 2)) then
            call fatal_error(error, path//"::/shapes/nmax: degree "//to_string(nmax(s))//" of shape " &
                             //to_string(s - 1)//" does not fit /shapes/coeffs", error_code%format)
            goto 99
         end if
         model%shapes(s) = sh_from_rows(coeffs(:, :, s), nmax(s))
      end do
      call h5_read_strings(f, "/shapes/name", model%shape_names, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/particles/shape", ivec, error)
      if (allocated(error)) goto 99
      model%np = size(ivec)
      model%shape = ivec + 1
      call h5_read(f, "/particles/center", model%center, error)
      if (allocated(error)) goto 99
      call h5_read(f, "/particles/rotation", rot, error)
      if (allocated(error)) goto 99
      if (any(shape(rot) /= [3, 3, model%np])) then
         call fatal_error(error, path//"::/particles/rotation: expected shape ("//to_string(model%np) &
                          //", 3, 3), one matrix per particle of /particles/shape", error_code%format)
         goto 99
      end if
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
      call h5_close(f, error)
      if (allocated(error)) return
      call validate_model(path, model, error)
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

   !> Check a model before it is used (run on every model read). Refuses, naming file::dataset and
   !> the first bad particle or value (0-based, as in the file): datasets of inconsistent length;
   !> box edges not finite or <= 0; a shape index outside /shapes; a particle order outside
   !> 0..nmax of its shape; a sieve index outside /sieves; a centre not finite; a scale not finite
   !> or <= 0; a rotation not finite, not orthonormal or a reflection (tolerance
   !> `rotation_tolerance` on every entry of R^T R - I and on det R - 1); shell thicknesses not
   !> finite or < 0. Shape coefficients (finite, a_00 > 0) are checked as they are read.
   subroutine validate_model(path, model, error)
      !> Model file (for messages).
      character(len=*), intent(in) :: path
      !> Model.
      type(model_type), intent(in) :: model
      !> Error naming file::dataset and the first bad value.
      type(error_type), allocatable, intent(out) :: error
      integer :: p, k, np, ns, nsieve
      real(wp) :: r(3, 3), dev, det

      np = model%np
      ns = size(model%shapes)
      nsieve = size(model%min_width)
      do k = 1, 3
         if (.not. (finite1(model%box(k)) .and. model%box(k) > 0.0_wp)) then
            call bad("/box/length", "edge "//to_string(k - 1)//" = "//to_string(model%box(k)) &
                     //" mm (must be finite and > 0)")
            return
         end if
      end do
      if (size(model%center, 1) /= 3 .or. size(model%center, 2) /= np) then
         call bad("/particles/center", "expected shape ("//to_string(np)//", 3), one centre per particle")
         return
      end if
      if (size(model%scale) /= np .or. size(model%nmax) /= np .or. size(model%sieve) /= np .or. &
          size(model%shell_thickness, 2) /= np) then
         call bad("/particles", "datasets of inconsistent length (/particles/shape has "//to_string(np)//")")
         return
      end if
      if (size(model%max_width) /= nsieve .or. size(model%target_fraction) /= nsieve .or. &
          size(model%achieved_fraction) /= nsieve .or. size(model%count) /= nsieve) then
         call bad("/sieves", "datasets of inconsistent length (/sieves/min_width has "//to_string(nsieve)//")")
         return
      end if
      if (size(model%shape_names) /= ns) then
         call bad("/shapes/name", to_string(size(model%shape_names))//" names for "//to_string(ns)//" shapes")
         return
      end if
      do p = 1, np
         if (model%shape(p) < 1 .or. model%shape(p) > ns) then
            call bad("/particles/shape", "particle "//to_string(p - 1)//": shape index "//to_string(model%shape(p) - 1) &
                     //" outside 0.."//to_string(ns - 1))
            return
         end if
         if (model%nmax(p) < 0 .or. model%nmax(p) > model%shapes(model%shape(p))%nmax) then
            call bad("/particles/nmax", "particle "//to_string(p - 1)//": order "//to_string(model%nmax(p)) &
                     //" outside 0.."//to_string(model%shapes(model%shape(p))%nmax)//" of its shape")
            return
         end if
         if (model%sieve(p) < 1 .or. model%sieve(p) > nsieve) then
            call bad("/particles/sieve", "particle "//to_string(p - 1)//": sieve index "//to_string(model%sieve(p) - 1) &
                     //" outside 0.."//to_string(nsieve - 1))
            return
         end if
         if (.not. all(finite(model%center(:, p)))) then
            call bad("/particles/center", "particle "//to_string(p - 1)//": centre ("//triple(model%center(:, p)) &
                     //") is not finite")
            return
         end if
         if (.not. (finite1(model%scale(p)) .and. model%scale(p) > 0.0_wp)) then
            call bad("/particles/scale", "particle "//to_string(p - 1)//": scale "//to_string(model%scale(p)) &
                     //" (must be finite and > 0)")
            return
         end if
         r = model%rotation(:, :, p)
         if (.not. all(finite(reshape(r, [9])))) then
            call bad("/particles/rotation", "particle "//to_string(p - 1)//": rotation is not finite")
            return
         end if
         dev = maxval(abs(matmul(transpose(r), r) - identity()))
         det = r(1, 1) * (r(2, 2) * r(3, 3) - r(2, 3) * r(3, 2)) - r(1, 2) * (r(2, 1) * r(3, 3) - r(2, 3) * r(3, 1)) &
               + r(1, 3) * (r(2, 1) * r(3, 2) - r(2, 2) * r(3, 1))
         if (dev > rotation_tolerance) then
            call bad("/particles/rotation", "particle "//to_string(p - 1)//": rotation is not orthonormal " &
                     //"(largest entry of |R^T R - I| = "//to_string(dev)//", tolerance "//to_string(rotation_tolerance)//")")
            return
         end if
         if (abs(det - 1.0_wp) > rotation_tolerance) then
            call bad("/particles/rotation", "particle "//to_string(p - 1)//": determinant "//to_string(det) &
                     //" (a reflection, not a rotation: must be +1 within "//to_string(rotation_tolerance)//")")
            return
         end if
         if (size(model%shell_thickness, 1) > 0) then
            if (.not. all(finite(model%shell_thickness(:, p)) .and. model%shell_thickness(:, p) >= 0.0_wp)) then
               call bad("/particles/shell_thickness", "particle "//to_string(p - 1)// &
                        ": thickness not finite or negative")
               return
            end if
         end if
      end do
   contains
      subroutine bad(dataset, what)
         character(len=*), intent(in) :: dataset, what
         call fatal_error(error, path//"::"//dataset//": "//what, error_code%format)
      end subroutine bad
   end subroutine validate_model

   elemental function finite(x) result(ok)
      real(wp), intent(in) :: x
      logical :: ok
      ok = x == x .and. abs(x) <= huge(x)
   end function finite

   pure function finite1(x) result(ok)
      real(wp), intent(in) :: x
      logical :: ok
      ok = x == x .and. abs(x) <= huge(x)
   end function finite1

   pure function identity() result(e)
      real(wp) :: e(3, 3)
      integer :: i
      e = 0.0_wp
      do i = 1, 3
         e(i, i) = 1.0_wp
      end do
   end function identity

   pure function triple(x) result(s)
      real(wp), intent(in) :: x(3)
      character(len=:), allocatable :: s
      s = to_string(x(1))//", "//to_string(x(2))//", "//to_string(x(3))
   end function triple
end module anm_io_model
