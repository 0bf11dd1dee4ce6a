!> `anm run FILE.nml [--force]`: read and validate the namelist, park, write the model file
!> (atomically), the summary table (stdout and CSV beside the model file) and the VRML file(s);
!> existing outputs are kept unless --force or `&output overwrite = .true.`. `anm rerun MODEL.h5
!> [--output DIR] [--force]`: the same for the namelist stored in a model file.
!>
!> Usage:
!>     call run_job("inputs/default.nml", output_unit, error_unit, error)
!>     call run_command(args(2:), output_unit, error_unit, error)   ! the command line after "run"
module anm_cli_run
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_filesystem, only: make_directory, join_path, is_directory, list_directory, string_type
   use anm_cli_arguments, only: is_option
   use anm_core_output, only: output_set_type, check_writable, remove_stale_temps
   use anm_core_resources, only: check_memory, particle_count_estimate, run_memory_estimate, shape_memory
   use anm_shapes_library, only: is_shape_file_name
   use anm_config_job, only: run_config_type, read_config
   use anm_config_shells, only: thickness_unit_keyword, shell_mode_name
   use anm_parking_engine, only: run_parking, particle_kind_type, body_holder, particle_share
   use anm_parking_scheduler, only: phase1_distributor_type
   use anm_parking_summary, only: write_summary, write_summary_csv_file
   use anm_io_model, only: model_type, write_model_file, read_model
   use anm_io_hdf5, only: h5_parallel_type
   use anm_io_vrml, only: vrml_mesh_type, write_vrml_file
   use anm_sh_expansion, only: sh_truncate
   implicit none
   private

   public :: run_job, run_command, rerun_command, check_run_resources, output_files

   !> Program version written into model files.
   character(len=*), parameter, public :: anm_version = "0.2.0"

contains

   !> `anm run FILE.nml [--force]` (the arguments after "run").
   subroutine run_command(args, out_unit, progress_unit, error, threads)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      !> Units for the summary table and the progress lines.
      integer, intent(in) :: out_unit, progress_unit
      !> Error (usage errors with error_code%usage).
      type(error_type), allocatable, intent(out) :: error
      !> Number of threads (recorded in the model file).
      integer, intent(in), optional :: threads
      character(len=:), allocatable :: path
      logical :: force
      integer :: i
      force = .false.
      do i = 1, size(args)
         if (args(i)%s == "--force") then
            force = .true.
         else if (is_option(args(i)%s)) then
            call fatal_error(error, "anm run: unknown option '"//args(i)%s//"'", error_code%usage)
            return
         else if (allocated(path)) then
            call fatal_error(error, "anm run: more than one namelist given ('"//path//"', '"//args(i)%s &
                             //"'); usage: anm run FILE.nml [--force]", error_code%usage)
            return
         else
            path = args(i)%s
         end if
      end do
      if (.not. allocated(path)) then
         call fatal_error(error, "usage: anm run FILE.nml [--force]", error_code%usage)
         return
      end if
      call run_job(path, out_unit, progress_unit, error, threads, force=force)
      if (allocated(error)) then
         if (index(error%message, "it is an HDF5 file") > 0) error%message = error%message &
            //"; to run again the namelist stored in a model file: anm rerun MODEL.h5 [--output DIR]"
      end if
   end subroutine run_command

   !> `anm rerun MODEL.h5 [--output DIR] [--force]`: the namelist stored in the model (/run/namelist)
   !> written to DIR/namelist.nml and run with its outputs in DIR (default: MODEL without ".h5",
   !> plus "-rerun").
   subroutine rerun_command(args, out_unit, progress_unit, error, threads)
      !> Arguments after the command name.
      type(string_type), intent(in) :: args(:)
      !> Units for the summary table and the progress lines.
      integer, intent(in) :: out_unit, progress_unit
      !> Error (usage errors with error_code%usage).
      type(error_type), allocatable, intent(out) :: error
      !> Number of threads (recorded in the model file).
      integer, intent(in), optional :: threads
      character(len=:), allocatable :: path, dir, nml
      logical :: force, exists
      integer :: i, u, stat
      character(len=256) :: msg
      type(model_type) :: model
      force = .false.
      i = 1
      do while (i <= size(args))
         if (args(i)%s == "--force") then
            force = .true.
         else if (args(i)%s == "--output") then
            if (i + 1 > size(args)) then
               call fatal_error(error, "option --output needs a value", error_code%usage)
               return
            end if
            dir = args(i + 1)%s
            i = i + 1
         else if (is_option(args(i)%s)) then
            call fatal_error(error, "anm rerun: unknown option '"//args(i)%s//"'", error_code%usage)
            return
         else if (allocated(path)) then
            call fatal_error(error, "anm rerun: more than one model given", error_code%usage)
            return
         else
            path = args(i)%s
         end if
         i = i + 1
      end do
      if (.not. allocated(path)) then
         call fatal_error(error, "usage: anm rerun MODEL.h5 [--output DIR] [--force]", error_code%usage)
         return
      end if
      call read_model(path, model, error)
      if (allocated(error)) return
      if (.not. allocated(dir)) then
         dir = path
         if (len(dir) > 3) then
            if (dir(len(dir) - 2:) == ".h5") dir = dir(:len(dir) - 3)
         end if
         dir = dir//"-rerun"
      end if
      call make_directory(dir, error)
      if (allocated(error)) return
      nml = join_path(dir, "namelist.nml")
      inquire (file=nml, exist=exists)
      if (exists .and. .not. force) then
         call fatal_error(error, nml//" exists: not overwritten (anm rerun --force, or another --output DIR)", &
                          error_code%io)
         return
      end if
      open (newunit=u, file=nml, status="replace", action="write", access="stream", form="unformatted", &
            iostat=stat, iomsg=msg)
      if (stat == 0) write (u, iostat=stat, iomsg=msg) model%namelist//new_line("a")
      if (stat == 0) close (u, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call fatal_error(error, nml//": "//trim(msg), error_code%io)
         return
      end if
      write (progress_unit, '(a)') "rerun: the namelist of "//path//" (kept as "//nml//"), outputs in "//dir
      call run_job(nml, out_unit, progress_unit, error, threads, force=force, directory=dir)
   end subroutine rerun_command

   !> Run the job of a namelist file.
   subroutine run_job(path, out_unit, progress_unit, error, threads, force, directory, dist, par)
      !> Namelist file.
      character(len=*), intent(in) :: path
      !> Unit for the summary table.
      integer, intent(in) :: out_unit
      !> Unit for progress lines.
      integer, intent(in) :: progress_unit
      !> Error naming the file and variable.
      type(error_type), allocatable, intent(out) :: error
      !> Number of threads (recorded in the model file).
      integer, intent(in), optional :: threads
      !> Overwrite existing outputs (as `&output overwrite = .true.`).
      logical, intent(in), optional :: force
      !> Output folder instead of the namelist's `&output directory`.
      character(len=*), intent(in), optional :: directory
      !> The MPI build: phase 1 spread over the processes, which all park the same model; only
      !> the writer checks the output folder, prints progress and writes the outputs.
      class(phase1_distributor_type), intent(in), optional :: dist
      !> The MPI build with parallel HDF5 (with `dist`): every process writes the model file
      !> together (collectively, to the writer's temporary name); the writer renames it once all
      !> have closed it, and writes the summary and VRML alone.
      class(h5_parallel_type), intent(in), optional :: par
      type(run_config_type) :: cfg
      type(model_type) :: model
      type(string_type), allocatable :: outputs(:), stale(:)
      logical :: overwrite, exists
      integer :: k
      type(particle_kind_type), allocatable :: kinds(:)
      integer, allocatable :: kind_of(:)
      character(len=:), allocatable :: dir, base, tmp, line
      type(output_set_type) :: set
      real(wp) :: share

      call read_config(path, cfg, error)
      if (allocated(error)) return
      if (present(directory)) cfg%output%directory = directory
      if (present(dist)) then
         if (.not. dist%writer) then
            call run_parking(cfg, model, kinds, kind_of, error, dist=dist)
            if (allocated(error)) return
            if (present(par)) then
               ! the writer's temporary name, then the collective write and the writer's rename
               call finish_model(cfg, model, threads)
               call agree_model(model, dist)
               call par%share(tmp)
               call write_model_file(tmp, model, error, par=par)
               if (allocated(error)) return
               call par%barrier()
            end if
            return
         end if
      end if
      dir = trim(cfg%output%directory)
      base = join_path(dir, trim(cfg%output%name))
      overwrite = cfg%output%overwrite
      if (present(force)) overwrite = overwrite .or. force
      if (.not. overwrite) then
         outputs = output_files(base, cfg%output%vrml, cfg%output%vrml_per_layer .and. cfg%shells%nlayer > 0, &
                                cfg%shells%nlayer)
         do k = 1, size(outputs)
            inquire (file=outputs(k)%s, exist=exists)
            if (exists) then
               call fatal_error(error, outputs(k)%s//" exists: not overwritten (anm run --force, or " &
                                //"&output overwrite = .true. in "//path//")", error_code%io)
               return
            end if
         end do
         ! an earlier run's VRML that this run would not replace (and so would remove)
         stale = obsolete_files(dir, trim(cfg%output%name), outputs)
         if (size(stale) > 0) then
            call fatal_error(error, stale(1)%s//" exists (VRML of an earlier run; this run writes " &
                             //"no such file and would remove it): not removed (anm run --force, or " &
                             //"&output overwrite = .true. in "//path//")", error_code%io)
            return
         end if
      end if
      call make_directory(dir, error)
      if (allocated(error)) then
         error%message = path//": &output: directory: "//error%message
         return
      end if
      ! before the long work: the output folder takes files, the request fits in memory
      call check_writable(dir, error)
      if (allocated(error)) then
         error%message = path//": &output: directory: "//error%message
         return
      end if
      if (present(dist)) then
         ! per process: its share of the particles (slabs), times the processes on this node
         share = 1.0_wp
         if (dist%spatial) share = particle_share(cfg, dist%nslab)
         call check_run_resources(cfg, error, share, dist%ranks_on_node)
      else
         call check_run_resources(cfg, error)
      end if
      if (allocated(error)) then
         error%message = path//": "//error%message
         return
      end if
      call remove_stale_temps(dir)
      call run_parking(cfg, model, kinds, kind_of, error, progress_unit, dist=dist)
      if (allocated(error)) return
      call finish_model(cfg, model, threads)
      ! every output to a temporary name first; renamed together once all are complete
      call set%add(base//".h5", tmp)
      if (present(par) .and. present(dist)) then
         ! all processes write the file together; renamed (commit) once every one has closed it
         call agree_model(model, dist)
         call par%share(tmp)
         call write_model_file(tmp, model, error, shown=base//".h5", par=par)
         if (allocated(error)) goto 99
         call par%barrier()
      else
         call write_model_file(tmp, model, error, shown=base//".h5")
         if (allocated(error)) goto 99
      end if
      call set%add(base//"-summary.csv", tmp)
      call write_summary_csv_file(tmp, model, error, shown=base//"-summary.csv")
      if (allocated(error)) goto 99
      if (cfg%output%vrml) then
         call write_model_vrml(cfg, model, kinds, kind_of, base, set, error)
         if (allocated(error)) goto 99
      end if
      ! an earlier run's VRML files of this name that this run does not write go with the set
      outputs = output_files(base, cfg%output%vrml, cfg%output%vrml_per_layer .and. cfg%shells%nlayer > 0, &
                             cfg%shells%nlayer)
      stale = obsolete_files(dir, trim(cfg%output%name), outputs)
      do k = 1, size(stale)
         call set%retire(stale(k)%s)
      end do
      call set%commit(error)
      if (allocated(error)) return
      call write_summary(out_unit, model)
      outputs = output_files(base, cfg%output%vrml, cfg%output%vrml_per_layer .and. cfg%shells%nlayer > 0, &
                             cfg%shells%nlayer)
      line = "model: "//outputs(1)%s//"; summary: "//outputs(2)%s
      if (size(outputs) > 2) line = line//"; VRML: "//outputs(3)%s
      do k = 4, size(outputs)
         line = line//", "//outputs(k)%s
      end do
      write (out_unit, '(a)') line
      flush (out_unit)
      return
99    call set%discard()
   end subroutine run_job

   !> The run's attributes of the model: program version, shell specification, threads.
   subroutine finish_model(cfg, model, threads)
      type(run_config_type), intent(in) :: cfg
      type(model_type), intent(inout) :: model
      integer, intent(in), optional :: threads
      model%version = anm_version
      ! the shell specification travels with the model (/shells)
      model%layer_thickness = cfg%shells%thickness
      model%layer_colour = cfg%shells%colour
      model%layer_unit = thickness_unit_keyword(cfg%shells%unit)
      model%layer_mode = shell_mode_name(cfg%shells%mode)
      if (present(threads)) model%threads = threads
   end subroutine finish_model

   !> The run attributes that differ between processes (wall time, threads) made the largest over
   !> them, so that every process writes the same attributes into a file written together
   !> (collective).
   subroutine agree_model(model, dist)
      type(model_type), intent(inout) :: model
      class(phase1_distributor_type), intent(in) :: dist
      model%wall_time = dist%agree(model%wall_time)
      model%threads = nint(dist%agree(real(model%threads, wp)))
   end subroutine agree_model

   !> The files a run writes for the output base name (DIR/NAME): the model, the summary and the
   !> VRML file, or one VRML file per layer.
   pure function output_files(base, vrml, per_layer, nlayer) result(files)
      !> DIR/NAME.
      character(len=*), intent(in) :: base
      !> VRML written; one file per layer.
      logical, intent(in) :: vrml, per_layer
      !> Number of shell layers.
      integer, intent(in) :: nlayer
      type(string_type), allocatable :: files(:)
      integer :: l
      files = [string_type(base//".h5"), string_type(base//"-summary.csv")]
      if (.not. vrml) return
      if (per_layer) then
         files = [files, string_type(base//"-particles.wrl")]
         do l = 1, nlayer
            files = [files, string_type(base//"-layer"//to_string(l)//".wrl")]
         end do
      else
         files = [files, string_type(base//".wrl")]
      end if
   end function output_files

   !> VRML files of output name `name` in folder `dir` (NAME.wrl, NAME-particles.wrl,
   !> NAME-layerK.wrl) that exist but are not among `outputs`: an earlier run's files that the
   !> current run does not replace.
   function obsolete_files(dir, name, outputs) result(stale)
      !> Output folder.
      character(len=*), intent(in) :: dir
      !> Output base name (&output name).
      character(len=*), intent(in) :: name
      !> The files this run writes.
      type(string_type), intent(in) :: outputs(:)
      type(string_type), allocatable :: stale(:)
      type(string_type), allocatable :: names(:)
      type(error_type), allocatable :: error
      character(len=:), allocatable :: entry, full
      integer :: i, k, n
      logical :: ours
      allocate (stale(0))
      call list_directory(dir, names, error)
      if (allocated(error)) return
      do i = 1, size(names)
         entry = names(i)%s
         n = len(entry)
         if (n < len(name) + 4) cycle
         if (entry(:len(name)) /= name .or. entry(n - 3:) /= ".wrl") cycle
         if (.not. vrml_suffix(entry(len(name) + 1:n - 4))) cycle
         full = join_path(dir, entry)
         ours = .false.
         do k = 1, size(outputs)
            if (outputs(k)%s == full) ours = .true.
         end do
         if (.not. ours) stale = [stale, string_type(full)]
      end do
   end function obsolete_files

   !> True for what follows the output name in a VRML file Anm writes: "", "-particles" or
   !> "-layerK" (K a positive integer).
   pure logical function vrml_suffix(tail)
      !> Text between the name and ".wrl".
      character(len=*), intent(in) :: tail
      vrml_suffix = .false.
      if (tail == "" .or. tail == "-particles") then
         vrml_suffix = .true.
      else if (len(tail) > 6) then
         if (tail(:6) == "-layer") vrml_suffix = verify(tail(7:), "0123456789") == 0
      end if
   end function vrml_suffix

   subroutine write_model_vrml(cfg, model, kinds, kind_of, base, set, error)
      type(run_config_type), intent(in) :: cfg
      type(model_type), intent(in) :: model
      type(particle_kind_type), intent(in) :: kinds(:)
      integer, intent(in) :: kind_of(:)
      character(len=*), intent(in) :: base
      type(output_set_type), intent(inout) :: set
      type(error_type), allocatable, intent(out) :: error
      type(vrml_mesh_type), allocatable :: meshes(:)
      integer, allocatable :: mesh_of(:), inst_of(:)
      real(wp), parameter :: palette(3, 6) = reshape([0.55_wp, 0.45_wp, 0.35_wp, 0.75_wp, 0.65_wp, 0.45_wp, &
                                                      0.85_wp, 0.80_wp, 0.60_wp, 0.60_wp, 0.60_wp, 0.65_wp, &
                                                      0.45_wp, 0.55_wp, 0.45_wp, 0.70_wp, 0.50_wp, 0.50_wp], [3, 6])
      integer :: nk, l, k, p, nlay, f, nfile, n
      character(len=:), allocatable :: name, tmp

      nk = size(kinds)
      nlay = cfg%shells%nlayer
      allocate (meshes(nk * (1 + nlay)))
      do k = 1, nk
         meshes(k)%shape = kinds(body_holder(kinds, k))%body%shape
         meshes(k)%tess = cfg%output%tessellation(kinds(k)%sieve)
         meshes(k)%colour = palette(:, 1 + mod(kinds(k)%sieve - 1, 6))
         do l = 1, nlay
            meshes(l * nk + k)%shape = sh_truncate(kinds(k)%layers(l), kinds(k)%layers(l)%nmax)
            meshes(l * nk + k)%tess = cfg%output%tessellation(kinds(k)%sieve)
            meshes(l * nk + k)%colour = cfg%shells%colour(:, l)
            meshes(l * nk + k)%transparency = 0.6_wp
         end do
      end do
      nfile = 1
      if (cfg%output%vrml_per_layer .and. nlay > 0) nfile = nlay + 1
      do f = 1, nfile
         if (nfile == 1) then
            n = model%np * (1 + nlay)
         else
            n = model%np
         end if
         allocate (mesh_of(n), inst_of(n))
         n = 0
         do l = 0, nlay
            if (nfile > 1 .and. l /= f - 1) cycle
            do p = 1, model%np
               n = n + 1
               mesh_of(n) = l * nk + kind_of(p)
               inst_of(n) = p
            end do
         end do
         if (nfile == 1) then
            name = base//".wrl"
         else if (f == 1) then
            name = base//"-particles.wrl"
         else
            name = base//"-layer"//to_string(f - 1)//".wrl"
         end if
         call set%add(name, tmp)
         call write_vrml_file(tmp, model%box, meshes, mesh_of, model%center(:, inst_of), &
                              model%rotation(:, :, inst_of), model%scale(inst_of), error, shown=name, &
                              layout=cfg%output%vrml_layout)
         if (allocated(error)) return
         deallocate (mesh_of, inst_of)
      end do
   end subroutine write_model_vrml

   !> Refuse a run whose memory estimate exceeds the memory available, before parking: particles
   !> (upper estimate from the box volume, the fractions and the smallest particle of each sieve),
   !> particle kinds (shapes times the sieves using them) and synthetic shapes. The message names
   !> the estimate and the variable to change. The MPI build passes the share of the particles a
   !> process holds and the processes on this machine, which share its memory.
   subroutine check_run_resources(cfg, error, share, processes)
      !> Validated configuration.
      type(run_config_type), intent(in) :: cfg
      !> Error naming the estimate and the variable to change.
      type(error_type), allocatable, intent(out) :: error
      !> Share of the particles one process holds (default 1).
      real(wp), intent(in), optional :: share
      !> Processes on this machine (default 1).
      integer, intent(in), optional :: processes
      real(wp) :: particles, kinds, synth, total
      integer :: s, nsynth
      character(len=:), allocatable :: variable

      associate (ns => cfg%sieves%nsieve)
         particles = particle_count_estimate(cfg%box%length, cfg%sieves%min_width(:ns), cfg%sieves%target_fraction(:ns))
      end associate
      kinds = 0.0_wp
      nsynth = 0
      do s = 1, cfg%sieves%nsieve
         if (trim(cfg%sieves%source(s)) == "synthetic") then
            kinds = kinds + real(max(0, cfg%synthetic%count), wp)
            nsynth = nsynth + 1
         else
            kinds = kinds + real(shape_file_count(trim(cfg%sieves%source(s))), wp)
         end if
      end do
      synth = 0.0_wp
      if (nsynth > 0) synth = shape_memory(real(max(0, cfg%synthetic%count), wp), cfg%synthetic%params%nmax)
      if (present(share)) particles = particles * share
      total = run_memory_estimate(particles, kinds, cfg%shells%nlayer) + synth
      if (present(processes)) total = total * max(1, processes)
      if (nsynth > 0 .and. synth + kinds * 5.0e6_wp > 0.5_wp * total) then
         variable = "&synthetic count (= "//to_string(cfg%synthetic%count)//")"
      else
         variable = "the box (&box length) or the fractions (&sieves fraction), or use larger sieves (about " &
                    //to_string(nint(min(particles, 1.0e15_wp), i8))//" particles estimated)"
      end if
      call check_memory(total, "this run", variable, error)
   end subroutine check_run_resources

   !> Number of shape files a source names (a folder: its *.dat files; a file: 1).
   function shape_file_count(source) result(n)
      character(len=*), intent(in) :: source
      integer :: n, i
      type(string_type), allocatable :: names(:)
      type(error_type), allocatable :: error
      n = 1
      if (.not. is_directory(source)) return
      call list_directory(source, names, error)
      if (allocated(error)) return
      n = 0
      do i = 1, size(names)
         if (is_shape_file_name(names(i)%s)) n = n + 1
      end do
   end function shape_file_count
end module anm_cli_run
