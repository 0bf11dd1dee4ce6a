!> `anm run FILE.nml`: read and validate the namelist, park, write the model file (atomically), the
!> summary table (stdout and CSV beside the model file) and the VRML file(s).
!>
!> Usage:
!>     call run_job("inputs/default.nml", output_unit, error_unit, error)
module anm_cli_run
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_filesystem, only: make_directory, join_path
   use anm_config_job, only: run_config_type, read_config
   use anm_config_shells, only: thickness_unit_keyword, shell_mode_name
   use anm_parking_engine, only: run_parking, particle_kind_type
   use anm_parking_summary, only: write_summary, write_summary_csv
   use anm_io_model, only: model_type, write_model
   use anm_io_vrml, only: vrml_mesh_type, write_vrml
   use anm_sh_expansion, only: sh_truncate
   implicit none
   private

   public :: run_job

   !> Program version written into model files.
   character(len=*), parameter, public :: anm_version = "0.2.0"

contains

   !> Run the job of a namelist file.
   subroutine run_job(path, out_unit, progress_unit, error, threads)
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
      type(run_config_type) :: cfg
      type(model_type) :: model
      type(particle_kind_type), allocatable :: kinds(:)
      integer, allocatable :: kind_of(:)
      character(len=:), allocatable :: dir, base

      call read_config(path, cfg, error)
      if (allocated(error)) return
      dir = trim(cfg%output%directory)
      call make_directory(dir, error)
      if (allocated(error)) then
         error%message = path//": &output: directory: "//error%message
         return
      end if
      base = join_path(dir, trim(cfg%output%name))
      call run_parking(cfg, model, kinds, kind_of, error, progress_unit)
      if (allocated(error)) return
      model%version = anm_version
      ! the shell specification travels with the model (/shells)
      model%layer_thickness = cfg%shells%thickness
      model%layer_colour = cfg%shells%colour
      model%layer_unit = thickness_unit_keyword(cfg%shells%unit)
      model%layer_mode = shell_mode_name(cfg%shells%mode)
      if (present(threads)) model%threads = threads
      call write_model(base//".h5", model, error)
      if (allocated(error)) return
      call write_summary(out_unit, model)
      call write_summary_csv(base//"-summary.csv", model, error)
      if (allocated(error)) return
      if (cfg%output%vrml) then
         call write_model_vrml(cfg, model, kinds, kind_of, base, error)
         if (allocated(error)) return
      end if
      write (out_unit, '(a)') "model: "//base//".h5; summary: "//base//"-summary.csv"// &
         merge("; VRML: "//base//".wrl", repeat(" ", len(base) + 12), cfg%output%vrml)
   end subroutine run_job

   subroutine write_model_vrml(cfg, model, kinds, kind_of, base, error)
      type(run_config_type), intent(in) :: cfg
      type(model_type), intent(in) :: model
      type(particle_kind_type), intent(in) :: kinds(:)
      integer, intent(in) :: kind_of(:)
      character(len=*), intent(in) :: base
      type(error_type), allocatable, intent(out) :: error
      type(vrml_mesh_type), allocatable :: meshes(:)
      integer, allocatable :: mesh_of(:), inst_of(:)
      real(wp), parameter :: palette(3, 6) = reshape([0.55_wp, 0.45_wp, 0.35_wp, 0.75_wp, 0.65_wp, 0.45_wp, &
                                                      0.85_wp, 0.80_wp, 0.60_wp, 0.60_wp, 0.60_wp, 0.65_wp, &
                                                      0.45_wp, 0.55_wp, 0.45_wp, 0.70_wp, 0.50_wp, 0.50_wp], [3, 6])
      integer :: nk, l, k, p, nlay, f, nfile, n
      character(len=:), allocatable :: name

      nk = size(kinds)
      nlay = cfg%shells%nlayer
      allocate (meshes(nk * (1 + nlay)))
      do k = 1, nk
         meshes(k)%shape = kinds(k)%body%shape
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
         call write_vrml(name, model%box, meshes, mesh_of, model%center(:, inst_of), model%rotation(:, :, inst_of), &
                         model%scale(inst_of), error)
         if (allocated(error)) return
         deallocate (mesh_of, inst_of)
      end do
   end subroutine write_model_vrml
end module anm_cli_run
