!> The commands of the `anm` program other than `run` (anm_cli_run): `shape`, `synth`, `verify`
!> and `study`, each reading its own arguments (the command name excluded) and writing its output
!> to a unit. The command-line contract, exit codes and bad-input rules: docs/cli.md.
!>
!> Usage:
!>     call shape_command(args(2:), output_unit, error)
!>     call verify_command(args(2:), output_unit, status, error)   ! status 3: overlap found
module anm_cli_commands
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_filesystem, only: join_path, make_directory, string_type
   use anm_cli_arguments, only: int_option, real_option, is_option
   use anm_cli_shape_table, only: write_geometry_header, write_geometry_row
   use anm_shapes_library, only: shape_set_type, load_shapes, synthetic_shapes, load_shape_file
   use anm_shapes_synthetic, only: synthetic_params_type
   use anm_shapes_nist, only: write_nist_shape
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_io_model, only: model_type, read_model
   use anm_audit_verify, only: verify_report_type, verify_model, verify_memory, verify_split_type
   use anm_core_resources, only: check_memory, shape_memory
   use anm_sh_expansion, only: sh_expansion_type
   use anm_contact_studies, only: study_next, study_nbox, nbox_range
   implicit none
   private

   public :: write_usage, write_command_usage, command_names, shape_command, synth_command, verify_command, &
      & study_command, verify_failed

   !> Exit status of `anm verify` when an overlap deeper than the tolerance is found.
   integer, parameter :: verify_failed = 3

   !> The commands, in the order of `anm --help`.
   character(len=6), parameter :: command_names(*) = [character(len=6) :: "run", "rerun", "verify", "shape", &
                                                      "synth", "study"]

contains

   !> The `anm --help` text: every command's usage.
   subroutine write_usage(unit)
      !> Output unit.
      integer, intent(in) :: unit
      integer :: k
      logical :: found
      write (unit, '(a)') "usage: anm COMMAND [ARGS]   (anm COMMAND --help: the usage of one command)", "", "commands:"
      do k = 1, size(command_names)
         call write_command_usage(unit, trim(command_names(k)), found)
      end do
      write (unit, '(a)') &
         "  --help, -h, --version", &
         "", &
         "Exit status: 0 success, 1 error, 2 usage error (unknown command or option, missing argument),", &
         "3 anm verify found an overlap. Environment: OMP_NUM_THREADS sets the number of threads."
   end subroutine write_usage

   !> The usage of one command (`anm COMMAND --help`); `found` is false for an unknown command.
   subroutine write_command_usage(unit, command, found)
      !> Output unit.
      integer, intent(in) :: unit
      !> Command name.
      character(len=*), intent(in) :: command
      !> Whether the command exists.
      logical, intent(out) :: found
      found = .true.
      select case (command)
      case ("run")
         write (unit, '(a)') &
            "  run FILE.nml [--force]", &
            "        build a model as the namelist says (docs/namelist.md): model file, summary table", &
            "        (stdout and CSV) and VRML in the output directory; progress on stderr. Existing", &
            "        outputs are not overwritten without --force (or &output overwrite = .true.)"
      case ("rerun")
         write (unit, '(a)') &
            "  rerun MODEL.h5 [--output DIR] [--force]", &
            "        run again the namelist stored in a model file (/run/namelist), into DIR (default:", &
            "        MODEL without .h5, plus -rerun); the namelist is kept there as DIR/namelist.nml"
      case ("shape")
         write (unit, '(a)') &
            "  shape FILE|DIR [--order N] [--next N]", &
            "        geometry table (NIST columns) of one coefficient file or of every *.dat in DIR,", &
            "        computed at expansion order N (default: all coefficients); --next N uses the", &
            "        thesis' extent scan with N angles instead of the refined extents"
      case ("synth")
         write (unit, '(a)') &
            "  synth DIR [--count N] [--seed S] [--order N] [--bc-mean X] [--bc-sd X] [--ab-mean X]", &
            "            [--ab-sd X] [--rough-c X] [--rough-beta X] [--sigma-rough X]", &
            "        write N synthetic aggregate-like shapes (default 24, seed 1, order 20) as NIST", &
            "        coefficient files DIR/synthetic-anm-NNNNN.dat; the spectrum parameters are", &
            "        described in docs/synthetic-shapes.md"
      case ("verify")
         write (unit, '(a)') &
            "  verify MODEL.h5 [--resolution N] [--tolerance MM] [--independent]", &
            "        audit a model: every neighbouring pair (periodic images included) that the certified", &
            "        contact test cannot prove disjoint, and the walls, by dense point sampling (N x 2N", &
            "        directions per particle, default 120); --independent samples every pair (no contact", &
            "        test at all: slower, independent of the parking path); exits with status 3 if any", &
            "        penetration exceeds the tolerance"
      case ("study")
         write (unit, '(a)') &
            "  study next|nbox SHAPE_FILE --csv OUT [--order N] [--seed S] [--nbox-range polar|eob]", &
            "        EOB parameter studies (docs/contact.md): next = extent-box volume vs N_ext,", &
            "        nbox = D_overlap vs N_box for two barely overlapping copies of the particle;", &
            "        --nbox-range: N_box spaces pi/N_box over the full polar range (polar, ours, default)", &
            "        or N_box points over the EOB's angular range (eob, the thesis)"
      case default
         found = .false.
      end select
   end subroutine write_command_usage

   !> `anm shape FILE|DIR [--order N] [--next N]`: the geometry table of the shapes.
   subroutine shape_command(args, unit, error)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      !> Output unit of the table.
      integer, intent(in) :: unit
      !> Error naming the option, argument or file.
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: path, arg
      integer :: i, order, next, k
      type(shape_set_type) :: set
      type(shape_geometry_type), allocatable :: geom(:)

      order = -1
      next = -1
      i = 1
      do while (i <= size(args))
         arg = args(i)%s
         select case (arg)
         case ("--order")
            call int_option(args, i, "--order", order, error, minimum=0)
            if (allocated(error)) return
         case ("--next")
            call int_option(args, i, "--next", next, error, minimum=2)
            if (allocated(error)) return
         case default
            if (is_option(arg)) then
               call fatal_error(error, "anm shape: unknown option '"//arg//"'", error_code%usage)
               return
            end if
            if (allocated(path)) then
               call fatal_error(error, "anm shape: more than one path given ('"//path//"', '"//arg//"')", &
                                error_code%usage)
               return
            end if
            path = arg
         end select
         i = i + 1
      end do
      if (.not. allocated(path)) then
         call fatal_error(error, "anm shape: missing FILE or DIR argument", error_code%usage)
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
      call write_geometry_header(unit)
      do k = 1, size(set%shapes)
         call write_geometry_row(unit, set%names(k)%s, geom(k))
      end do
   end subroutine shape_command

   !> `anm synth DIR [options]`: write synthetic shapes as NIST coefficient files.
   subroutine synth_command(args, unit, error)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      !> Output unit of the closing line.
      integer, intent(in) :: unit
      !> Error naming the option, argument or file.
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir, arg
      integer :: i, count, seed, k
      type(synthetic_params_type) :: par
      type(shape_set_type) :: set

      count = 24
      seed = 1
      i = 1
      do while (i <= size(args))
         arg = args(i)%s
         select case (arg)
         case ("--count")
            call int_option(args, i, "--count", count, error, minimum=1)
         case ("--seed")
            call int_option(args, i, "--seed", seed, error)
         case ("--order")
            call int_option(args, i, "--order", par%nmax, error)
         case ("--bc-mean")
            call real_option(args, i, "--bc-mean", par%bc_mean, error)
         case ("--bc-sd")
            call real_option(args, i, "--bc-sd", par%bc_sd, error)
         case ("--ab-mean")
            call real_option(args, i, "--ab-mean", par%ab_mean, error)
         case ("--ab-sd")
            call real_option(args, i, "--ab-sd", par%ab_sd, error)
         case ("--rough-c")
            call real_option(args, i, "--rough-c", par%rough_c, error)
         case ("--rough-beta")
            call real_option(args, i, "--rough-beta", par%rough_beta, error)
         case ("--sigma-rough")
            call real_option(args, i, "--sigma-rough", par%sigma_rough, error)
         case default
            if (is_option(arg)) then
               call fatal_error(error, "anm synth: unknown option '"//arg//"'", error_code%usage)
               return
            end if
            dir = arg
         end select
         if (allocated(error)) return
         i = i + 1
      end do
      if (.not. allocated(dir)) then
         call fatal_error(error, "anm synth: missing output DIR argument", error_code%usage)
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
      write (unit, '(a)') "wrote "//to_string(count)//" synthetic shapes to "//dir
   end subroutine synth_command

   !> `anm verify MODEL.h5 [--resolution N] [--tolerance MM] [--independent]`: the overlap audit of a model.
   !> With `split` (the MPI build), every process audits its slab of the model and process 0
   !> writes the combined report (docs/mpi.md).
   subroutine verify_command(args, unit, status, error, split)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      !> Output unit of the report.
      integer, intent(in) :: unit
      !> 0, or `verify_failed` when an overlap or wall violation deeper than the tolerance is found.
      integer, intent(out) :: status
      !> Error naming the option, argument or file.
      type(error_type), allocatable, intent(out) :: error
      !> Processes auditing the model together.
      class(verify_split_type), intent(in), optional :: split
      character(len=:), allocatable :: path, arg
      integer :: i, resolution
      real(wp) :: tol
      logical :: have_tol, independent
      type(model_type) :: model
      type(verify_report_type) :: rep

      status = 0
      resolution = 120
      have_tol = .false.
      independent = .false.
      tol = 0.0_wp
      i = 1
      do while (i <= size(args))
         arg = args(i)%s
         select case (arg)
         case ("--resolution")
            call int_option(args, i, "--resolution", resolution, error, minimum=4)
            if (allocated(error)) return
         case ("--tolerance")
            call real_option(args, i, "--tolerance", tol, error)
            if (allocated(error)) return
            have_tol = .true.
         case ("--independent")
            independent = .true.
         case default
            if (is_option(arg)) then
               call fatal_error(error, "anm verify: unknown option '"//arg//"'", error_code%usage)
               return
            end if
            path = arg
         end select
         i = i + 1
      end do
      if (.not. allocated(path)) then
         call fatal_error(error, "anm verify: missing MODEL.h5 argument", error_code%usage)
         return
      end if
      call read_model(path, model, error)
      if (allocated(error)) return
      if (independent) then
         call check_memory(verify_memory(model, resolution, filter=.false.), "anm verify --resolution " &
                           //to_string(resolution), "--resolution", error)
      else
         call check_memory(verify_memory(model, resolution), "anm verify --resolution "//to_string(resolution), &
                           "--resolution", error)
      end if
      if (allocated(error)) return
      ! the default tolerance is verify_model's own (1e-4 of the smallest sieve width)
      if (.not. have_tol) tol = 1.0e-4_wp * minval(model%min_width)
      if (independent) then
         call verify_model(model, resolution, rep, tol, filter=.false., split=split)
      else if (have_tol) then
         call verify_model(model, resolution, rep, tol, split=split)
      else
         call verify_model(model, resolution, rep, split=split)
      end if
      if (present(split)) then
         if (split%rank == 0) call write_verify_report(unit, path, model, rep)
      else
         call write_verify_report(unit, path, model, rep)
      end if
      if (rep%overlapping_pairs > 0 .or. rep%wall_violations > 0) status = verify_failed
   end subroutine verify_command

   !> The report of `anm verify`.
   subroutine write_verify_report(unit, path, model, rep)
      !> Output unit.
      integer, intent(in) :: unit
      !> Model file.
      character(len=*), intent(in) :: path
      !> The model.
      type(model_type), intent(in) :: model
      !> The audit.
      type(verify_report_type), intent(in) :: rep
      write (unit, '(a)') "verify "//path
      write (unit, '(a,i0)') "  particles:            ", model%np
      write (unit, '(a,i0,a)') "  samples per particle: ", rep%samples, " directions"
      write (unit, '(a,i0)') "  pairs checked:        ", rep%pairs_checked
      write (unit, '(a,i0)') "  of which cleared by the certified contact test: ", rep%pairs_cleared
      write (unit, '(a,i0)') "  overlapping pairs:    ", rep%overlapping_pairs
      if (.not. model%periodic) write (unit, '(a,i0)') "  wall violations:      ", rep%wall_violations
      write (unit, '(a,es12.5,a)') "  largest penetration:  ", rep%max_depth, " mm"
      if (rep%worst(1) > 0) write (unit, '(a,i0,a,i0)') "  deepest pair:         particles ", &
         rep%worst(1) - 1, " and ", rep%worst(2) - 1
      write (unit, '(a,es12.5,a)') "  tolerance:            ", rep%tolerance, " mm"
      if (rep%overlapping_pairs > 0 .or. rep%wall_violations > 0) then
         write (unit, '(a)') "  result: FAIL (overlap deeper than the tolerance)"
      else
         write (unit, '(a)') "  result: OK"
      end if
   end subroutine write_verify_report

   !> `anm study next|nbox SHAPE_FILE --csv OUT [--order N] [--seed S] [--nbox-range polar|eob]`: the
   !> EOB parameter studies.
   subroutine study_command(args, unit, error)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      !> Output unit of the closing line.
      integer, intent(in) :: unit
      !> Error naming the option, argument or file.
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: kind, path, csv, arg
      integer :: i, order, seed, reading
      type(sh_expansion_type) :: shape

      reading = nbox_range%polar
      order = -1
      seed = 1
      i = 1
      do while (i <= size(args))
         arg = args(i)%s
         select case (arg)
         case ("--csv")
            if (i + 1 > size(args)) then
               call fatal_error(error, "option --csv needs a value", error_code%usage)
               return
            end if
            csv = args(i + 1)%s
            i = i + 1
         case ("--order")
            call int_option(args, i, "--order", order, error)
         case ("--seed")
            call int_option(args, i, "--seed", seed, error)
         case ("--nbox-range")
            if (i + 1 > size(args)) then
               call fatal_error(error, "option --nbox-range needs a value (polar or eob)", error_code%usage)
               return
            end if
            select case (args(i + 1)%s)
            case ("polar")
               reading = nbox_range%polar
            case ("eob")
               reading = nbox_range%eob
            case default
               call fatal_error(error, "anm study: --nbox-range '"//args(i + 1)%s//"' must be polar or eob", &
                                error_code%usage)
               return
            end select
            i = i + 1
         case default
            if (is_option(arg)) then
               call fatal_error(error, "anm study: unknown option '"//arg//"'", error_code%usage)
            else if (.not. allocated(kind)) then
               kind = arg
            else if (.not. allocated(path)) then
               path = arg
            else
               call fatal_error(error, "anm study: unexpected argument '"//arg//"'", error_code%usage)
            end if
         end select
         if (allocated(error)) return
         i = i + 1
      end do
      if (.not. allocated(kind) .or. .not. allocated(path) .or. .not. allocated(csv)) then
         call fatal_error(error, "anm study: usage: anm study next|nbox SHAPE_FILE --csv OUT", error_code%usage)
         return
      end if
      call load_shape_file(path, shape, error)
      if (allocated(error)) return
      select case (kind)
      case ("next")
         call study_next(shape, order, csv, error)
      case ("nbox")
         call study_nbox(shape, order, seed, csv, error, reading)
      case default
         call fatal_error(error, "anm study: unknown study '"//kind//"' (next or nbox)", error_code%usage)
      end select
      if (allocated(error)) return
      write (unit, '(a)') "wrote "//csv
   end subroutine study_command
end module anm_cli_commands
