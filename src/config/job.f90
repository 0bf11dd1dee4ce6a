!> The configuration of a run: one record per namelist group, read and validated group by group
!> from one scan of the file, and written back fully resolved (defaults included) into the model
!> file (`/run/resolved_namelist`). This module is the area's facade: it re-exports the records
!> and the enumerators.
!>
!> Groups (every variable, unit, default and range: docs/namelist.md):
!>     &box       length, periodic                                      (required)
!>     &sieves    nsieve, min_width, max_width, fraction, fraction_mode, total_fraction, source, order
!>                                                                      (required)
!>     &synthetic count, nmax, bc_mean, bc_sd, ab_mean, ab_sd, rough_c, rough_beta, sigma_rough
!>     &parking   max_locations, max_orientations, max_sizes, max_shapes, max_failures, contact_method,
!>                n_ext, n_box, certified, placement
!>     &shells    nlayer, thickness, thickness_unit, mode, colour
!>     &output    directory, name, vrml, vrml_per_layer, tessellation
!>     &run       seed
!>
!> Choices are resolved once to enumerators: `placement%uniform|void`,
!> `contact_method%eob|newton_raphson`, `shell_mode%exclude|shell_overlap|overlap`,
!> `thickness_unit%mm|fraction_of_length`.
!>
!> Usage:
!>     type(run_config_type) :: cfg
!>     call read_config("inputs/default.nml", cfg, error)
!>     if (allocated(error)) return
!>     if (cfg%parking%placement == placement%void) ...
!>     text = write_config(cfg)          ! the resolved namelist
module anm_config_job
   use anm_core_error, only: error_type
   use anm_config_namelist, only: namelist_file_type, scan_namelist
   use anm_config_box, only: box_config_type, load_box_config, dump_box_config
   use anm_config_sieves, only: sieves_config_type, load_sieves_config, dump_sieves_config, max_sieves
   use anm_config_synthetic, only: synthetic_config_type, load_synthetic_config, dump_synthetic_config
   use anm_config_parking, only: parking_config_type, load_parking_config, dump_parking_config, placement, &
      & contact_method
   use anm_config_shells, only: shells_config_type, load_shells_config, dump_shells_config, shell_mode, &
      & thickness_unit, max_layers
   use anm_config_output, only: output_config_type, load_output_config, dump_output_config, vrml_layout
   use anm_config_run, only: run_group_config_type, load_run_group_config, dump_run_group_config
   implicit none
   private

   public :: run_config_type, read_config, write_config, known_groups
   public :: box_config_type, sieves_config_type, synthetic_config_type, parking_config_type, shells_config_type, &
      & output_config_type, run_group_config_type
   public :: placement, contact_method, shell_mode, thickness_unit, max_sieves, max_layers, vrml_layout

   !> The namelist groups the program knows, in reading order.
   character(len=9), parameter :: known_groups(7) = [character(len=9) :: "box", "sieves", "synthetic", &
                                                     "parking", "shells", "output", "run"]

   !> Everything a run needs, resolved and validated.
   type :: run_config_type
      !> Input file name.
      character(len=:), allocatable :: file
      !> Full text of the input file (stored in the model file as `/run/namelist`).
      character(len=:), allocatable :: text
      !> `&box`.
      type(box_config_type) :: box
      !> `&sieves`.
      type(sieves_config_type) :: sieves
      !> `&synthetic`.
      type(synthetic_config_type) :: synthetic
      !> `&parking`.
      type(parking_config_type) :: parking
      !> `&shells`.
      type(shells_config_type) :: shells
      !> `&output`.
      type(output_config_type) :: output
      !> `&run`.
      type(run_group_config_type) :: run
   end type run_config_type

contains

   !> Read, resolve and validate a namelist file. Every error names the file, the line, the group
   !> and the variable; nothing is run before the whole file is valid.
   subroutine read_config(path, cfg, error)
      !> Namelist file.
      character(len=*), intent(in) :: path
      !> Resolved configuration.
      type(run_config_type), intent(out) :: cfg
      !> Error naming file, line, group, variable.
      type(error_type), allocatable, intent(out) :: error
      type(namelist_file_type) :: nml

      cfg%file = path
      call scan_namelist(path, known_groups, nml, error)
      if (allocated(error)) return
      cfg%text = nml%text
      call load_box_config(cfg%box, nml, error)
      if (allocated(error)) return
      call load_sieves_config(cfg%sieves, nml, cfg%box, error)
      if (allocated(error)) return
      call load_synthetic_config(cfg%synthetic, nml, error)
      if (allocated(error)) return
      call load_parking_config(cfg%parking, nml, error)
      if (allocated(error)) return
      call load_shells_config(cfg%shells, nml, error)
      if (allocated(error)) return
      call load_output_config(cfg%output, nml, cfg%sieves%nsieve, error)
      if (allocated(error)) return
      call load_run_group_config(cfg%run, nml, error)
   end subroutine read_config

   !> The fully resolved configuration (defaults included) as namelist text: what really ran.
   pure function write_config(cfg) result(text)
      !> Configuration.
      type(run_config_type), intent(in) :: cfg
      character(len=:), allocatable :: text
      text = dump_box_config(cfg%box)//dump_sieves_config(cfg%sieves)//dump_synthetic_config(cfg%synthetic) &
             //dump_parking_config(cfg%parking)//dump_shells_config(cfg%shells)//dump_output_config(cfg%output) &
             //dump_run_group_config(cfg%run)
   end function write_config
end module anm_config_job
