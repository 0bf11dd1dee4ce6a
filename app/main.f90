!> The `anm` command: parses the command line, calls the library and turns errors into messages
!> and exit codes. See `anm --help` and docs/user-guide.md.
program anm
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_filesystem, only: join_path, make_directory
   use anm_shapes_library, only: shape_set_type, load_shapes, synthetic_shapes
   use anm_shapes_synthetic, only: synthetic_params_type
   use anm_shapes_nist, only: write_nist_shape
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_cli_shape_table, only: write_geometry_header, write_geometry_row
   use anm_io_model, only: model_type, read_model
   use anm_audit_verify, only: verify_report_type, verify_model
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_library, only: load_shape_file
   use anm_contact_studies, only: study_next, study_nbox
   use anm_cli_run, only: run_job, anm_version
   use anm_audit_verify, only: verify_memory
   use anm_core_output, only: ignore_file_size_signal
   use anm_core_resources, only: check_memory, shape_memory
   use omp_lib, only: omp_get_max_threads
   implicit none

   character(len=:), allocatable :: command
   type(error_type), allocatable :: error
   integer :: threads

   threads = omp_get_max_threads()
   call ignore_file_size_signal()   ! a file-size limit gives EFBIG, reported as an error

   if (command_argument_count() < 1) then
      call usage(error_unit)
      call exit(2)
   end if
   command = argument(1)
   select case (command)
   case ("-h", "--help", "help")
      call usage(output_unit)
   case ("--version")
      write (output_unit, '(a)') "anm "//anm_version
   case ("shape")
      call run_shape(error)
   case ("synth")
      call run_synth(error)
   case ("verify")
      call run_verify(error)
   case ("study")
      call run_study(error)
   case ("run")
      if (command_argument_count() /= 2) then
         call fatal_error(error, "usage: anm run FILE.nml", error_code%value)
      else
         call run_job(argument(2), output_unit, error_unit, error, threads)
      end if
   case default
      call fatal_error(error, "unknown command '"//command//"' (try: anm --help)", error_code%value)
   end select
   if (allocated(error)) then
      write (error_unit, '(a)') "anm: error: "//error%message
      call exit(1)
   end if

contains

   subroutine usage(unit)
      integer, intent(in) :: unit
      write (unit, '(a)') &
         "usage: anm COMMAND [ARGS]", &
         "", &
         "commands:", &
         "  run FILE.nml", &
         "        build a model as the namelist says (docs/namelist.md): model file, summary table", &
         "        (stdout and CSV) and VRML in the output directory; progress on stderr", &
         "  shape FILE|DIR [--order N] [--next N]", &
         "        geometry table (NIST columns) of one coefficient file or of every *.dat in DIR,", &
         "        computed at expansion order N (default: all coefficients); --next N uses the", &
         "        thesis' extent scan with N angles instead of the refined extents", &
         "  synth DIR [--count N] [--seed S] [--order N] [--bc-mean X] [--bc-sd X] [--ab-mean X]", &
         "            [--ab-sd X] [--rough-c X] [--rough-beta X] [--sigma-rough X]", &
         "        write N synthetic aggregate-like shapes (default 24, seed 1, order 20) as NIST", &
         "        coefficient files DIR/synthetic-anm-NNNNN.dat; the spectrum parameters are", &
         "        described in docs/synthetic-shapes.md", &
         "  verify MODEL.h5 [--resolution N] [--tolerance MM]", &
         "        audit a model independently of the parking path: every neighbouring pair (periodic", &
         "        images included) and the walls, by dense point sampling (N x 2N directions per", &
         "        particle, default 120); exits with status 3 if any penetration exceeds the tolerance", &
         "  study next|nbox SHAPE_FILE --csv OUT [--order N] [--seed S]", &
         "        EOB parameter studies (docs/contact.md): next = extent-box volume vs N_ext,", &
         "        nbox = D_overlap vs N_box for two barely overlapping copies of the particle", &
         "  --help, --version", &
         "", &
         "Environment: OMP_NUM_THREADS sets the number of threads."
   end subroutine usage

   function argument(i) result(arg)
      integer, intent(in) :: i
      character(len=:), allocatable :: arg
      integer :: length
      call get_command_argument(i, length=length)
      allocate (character(len=length) :: arg)
      if (length > 0) call get_command_argument(i, arg)
   end function argument

   !> Text of the value of option `name` (argument i+1), checked against the allowed characters;
   !> advances i past the value.
   subroutine option_text(i, name, allowed, what, text, error)
      integer, intent(inout) :: i
      character(len=*), intent(in) :: name, allowed, what
      character(len=:), allocatable, intent(out) :: text
      type(error_type), allocatable, intent(out) :: error
      if (i + 1 > command_argument_count()) then
         call fatal_error(error, "option "//name//" needs a value", error_code%value)
         return
      end if
      text = argument(i + 1)
      if (len(text) == 0 .or. verify(text, allowed) /= 0) then
         call fatal_error(error, "option "//name//": '"//text//"' is not "//what, error_code%value)
         return
      end if
      i = i + 1
   end subroutine option_text

   !> Integer value of option `name` at argument position i+1, at least `minimum` when given.
   subroutine int_option(i, name, val, error, minimum)
      integer, intent(inout) :: i
      character(len=*), intent(in) :: name
      integer, intent(out) :: val
      type(error_type), allocatable, intent(out) :: error
      integer, intent(in), optional :: minimum
      character(len=:), allocatable :: text
      integer :: stat
      call option_text(i, name, "+-0123456789", "an integer", text, error)
      if (allocated(error)) return
      read (text, *, iostat=stat) val
      if (stat /= 0) then
         call fatal_error(error, "option "//name//": '"//text//"' is not an integer", error_code%value)
      else if (present(minimum)) then
         if (val < minimum) call fatal_error(error, "option "//name//": "//to_string(val)//" must be >= " &
                                             //to_string(minimum), error_code%value)
      end if
   end subroutine int_option

   !> Real value of option `name` at argument position i+1.
   subroutine real_option(i, name, val, error)
      integer, intent(inout) :: i
      character(len=*), intent(in) :: name
      real(wp), intent(out) :: val
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: text
      integer :: stat
      call option_text(i, name, "+-.0123456789eEdD", "a number", text, error)
      if (allocated(error)) return
      read (text, *, iostat=stat) val
      if (stat /= 0) call fatal_error(error, "option "//name//": '"//text//"' is not a number", error_code%value)
   end subroutine real_option

   subroutine run_shape(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: path, arg
      integer :: i, order, next, k
      type(shape_set_type) :: set
      type(shape_geometry_type), allocatable :: geom(:)

      order = -1
      next = -1
      i = 2
      do while (i <= command_argument_count())
         arg = argument(i)
         select case (arg)
         case ("--order")
            call int_option(i, "--order", order, error, minimum=0)
            if (allocated(error)) return
         case ("--next")
            call int_option(i, "--next", next, error, minimum=2)
            if (allocated(error)) return
         case default
            if (arg(1:min(1, len(arg))) == "-") then
               call fatal_error(error, "anm shape: unknown option '"//arg//"'", error_code%value)
               return
            end if
            if (allocated(path)) then
               call fatal_error(error, "anm shape: more than one path given ('"//path//"', '"//arg//"')", &
                                error_code%value)
               return
            end if
            path = arg
         end select
         i = i + 1
      end do
      if (.not. allocated(path)) then
         call fatal_error(error, "anm shape: missing FILE or DIR argument", error_code%value)
         return
      end if
      call load_shapes(path, set, error)
      if (allocated(error)) return
      allocate (geom(size(set%shapes)))
      !$omp parallel do default(none) shared(set, geom, order, next) private(k) schedule(dynamic)
      do k = 1, size(set%shapes)
         if (order >= 0 .and. next >= 2) then
            call compute_geometry(set%shapes(k), geom(k), nused=order, next=next)
         else if (order >= 0) then
            call compute_geometry(set%shapes(k), geom(k), nused=order)
         else if (next >= 2) then
            call compute_geometry(set%shapes(k), geom(k), next=next)
         else
            call compute_geometry(set%shapes(k), geom(k))
         end if
      end do
      !$omp end parallel do
      call write_geometry_header(output_unit)
      do k = 1, size(set%shapes)
         call write_geometry_row(output_unit, set%names(k)%s, geom(k))
      end do
   end subroutine run_shape

   subroutine run_synth(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir, arg
      integer :: i, count, seed, k
      type(synthetic_params_type) :: par
      type(shape_set_type) :: set

      count = 24
      seed = 1
      i = 2
      do while (i <= command_argument_count())
         arg = argument(i)
         select case (arg)
         case ("--count")
            call int_option(i, "--count", count, error)
         case ("--seed")
            call int_option(i, "--seed", seed, error)
         case ("--order")
            call int_option(i, "--order", par%nmax, error)
         case ("--bc-mean")
            call real_option(i, "--bc-mean", par%bc_mean, error)
         case ("--bc-sd")
            call real_option(i, "--bc-sd", par%bc_sd, error)
         case ("--ab-mean")
            call real_option(i, "--ab-mean", par%ab_mean, error)
         case ("--ab-sd")
            call real_option(i, "--ab-sd", par%ab_sd, error)
         case ("--rough-c")
            call real_option(i, "--rough-c", par%rough_c, error)
         case ("--rough-beta")
            call real_option(i, "--rough-beta", par%rough_beta, error)
         case ("--sigma-rough")
            call real_option(i, "--sigma-rough", par%sigma_rough, error)
         case default
            if (arg(1:min(1, len(arg))) == "-") then
               call fatal_error(error, "anm synth: unknown option '"//arg//"'", error_code%value)
               return
            end if
            dir = arg
         end select
         if (allocated(error)) return
         i = i + 1
      end do
      if (.not. allocated(dir)) then
         call fatal_error(error, "anm synth: missing output DIR argument", error_code%value)
         return
      end if
      call check_memory(shape_memory(real(max(0, count), wp), par%nmax), "anm synth --count "//to_string(count), &
                        "--count", error)
      if (allocated(error)) return
      call synthetic_shapes(par, int(seed, i8), count, set, error)
      if (allocated(error)) return
      call make_directory(dir, error)
      if (allocated(error)) return
      do k = 1, count
         call write_nist_shape(join_path(dir, set%names(k)%s), set%shapes(k), error)
         if (allocated(error)) return
      end do
      write (output_unit, '(a)') "wrote "//to_string(count)//" synthetic shapes to "//dir
   end subroutine run_synth

   subroutine run_verify(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: path, arg
      integer :: i, resolution
      real(wp) :: tol
      logical :: have_tol
      type(model_type) :: model
      type(verify_report_type) :: rep

      resolution = 120
      have_tol = .false.
      tol = 0.0_wp
      i = 2
      do while (i <= command_argument_count())
         arg = argument(i)
         select case (arg)
         case ("--resolution")
            call int_option(i, "--resolution", resolution, error, minimum=4)
            if (allocated(error)) return
         case ("--tolerance")
            call real_option(i, "--tolerance", tol, error)
            if (allocated(error)) return
            have_tol = .true.
         case default
            if (arg(1:min(1, len(arg))) == "-") then
               call fatal_error(error, "anm verify: unknown option '"//arg//"'", error_code%value)
               return
            end if
            path = arg
         end select
         i = i + 1
      end do
      if (.not. allocated(path)) then
         call fatal_error(error, "anm verify: missing MODEL.h5 argument", error_code%value)
         return
      end if
      call read_model(path, model, error)
      if (allocated(error)) return
      call check_memory(verify_memory(model, resolution), "anm verify --resolution "//to_string(resolution), &
                        "--resolution", error)
      if (allocated(error)) return
      if (have_tol) then
         call verify_model(model, resolution, rep, tol)
      else
         call verify_model(model, resolution, rep)
      end if
      write (output_unit, '(a)') "verify "//path
      write (output_unit, '(a,i0)') "  particles:            ", model%np
      write (output_unit, '(a,i0,a)') "  samples per particle: ", rep%samples, " directions"
      write (output_unit, '(a,i0)') "  pairs checked:        ", rep%pairs_checked
      write (output_unit, '(a,i0)') "  overlapping pairs:    ", rep%overlapping_pairs
      if (.not. model%periodic) write (output_unit, '(a,i0)') "  wall violations:      ", rep%wall_violations
      write (output_unit, '(a,es12.5,a)') "  largest penetration:  ", rep%max_depth, " mm"
      if (rep%worst(1) > 0) write (output_unit, '(a,i0,a,i0)') "  deepest pair:         particles ", &
         rep%worst(1) - 1, " and ", rep%worst(2) - 1
      write (output_unit, '(a,es12.5,a)') "  tolerance:            ", rep%tolerance, " mm"
      if (rep%overlapping_pairs > 0 .or. rep%wall_violations > 0) then
         write (output_unit, '(a)') "  result: FAIL (overlap deeper than the tolerance)"
         call exit(3)
      end if
      write (output_unit, '(a)') "  result: OK"
   end subroutine run_verify
   subroutine run_study(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: kind, path, csv, arg
      integer :: i, order, seed
      type(sh_expansion_type) :: shape
      order = -1
      seed = 1
      i = 2
      do while (i <= command_argument_count())
         arg = argument(i)
         select case (arg)
         case ("--csv")
            if (i + 1 > command_argument_count()) then
               call fatal_error(error, "option --csv needs a value", error_code%value)
               return
            end if
            csv = argument(i + 1)
            i = i + 1
         case ("--order")
            call int_option(i, "--order", order, error)
         case ("--seed")
            call int_option(i, "--seed", seed, error)
         case default
            if (arg(1:min(1, len(arg))) == "-") then
               call fatal_error(error, "anm study: unknown option '"//arg//"'", error_code%value)
            else if (.not. allocated(kind)) then
               kind = arg
            else if (.not. allocated(path)) then
               path = arg
            else
               call fatal_error(error, "anm study: unexpected argument '"//arg//"'", error_code%value)
            end if
         end select
         if (allocated(error)) return
         i = i + 1
      end do
      if (.not. allocated(kind) .or. .not. allocated(path) .or. .not. allocated(csv)) then
         call fatal_error(error, "anm study: usage: anm study next|nbox SHAPE_FILE --csv OUT", error_code%value)
         return
      end if
      call load_shape_file(path, shape, error)
      if (allocated(error)) return
      select case (kind)
      case ("next")
         call study_next(shape, order, csv, error)
      case ("nbox")
         call study_nbox(shape, order, seed, csv, error)
      case default
         call fatal_error(error, "anm study: unknown study '"//kind//"' (next or nbox)", error_code%value)
      end select
      if (allocated(error)) return
      write (output_unit, '(a)') "wrote "//csv
   end subroutine run_study
end program anm
