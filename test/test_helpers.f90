!> Helpers shared by the Fortran test suites.
module test_helpers
   use anm_core_error, only: error_type
   use anm_config_job, only: run_config_type, read_config
   use anm_parking_engine, only: run_parking, particle_kind_type
   use anm_io_model, only: model_type
   implicit none
   private

   public :: run_nml

contains

   !> Park the namelist `text` (written to build/test-tmp/NAME) as `anm run` would, without
   !> writing outputs; `max_batch` as run_parking's (1: the plain serial algorithm).
   subroutine run_nml(name, text, model, error, max_batch)
      !> File name of the namelist under build/test-tmp.
      character(len=*), intent(in) :: name
      !> Namelist text.
      character(len=*), intent(in) :: text
      !> The parked model.
      type(model_type), intent(out) :: model
      !> Error of the configuration or the parking.
      type(error_type), allocatable, intent(out) :: error
      !> Largest batch of speculated particles.
      integer, intent(in), optional :: max_batch
      type(run_config_type) :: cfg
      type(particle_kind_type), allocatable :: kinds(:)
      integer, allocatable :: kind_of(:)
      integer :: unit
      call execute_command_line("mkdir -p build/test-tmp")
      open (newunit=unit, file="build/test-tmp/"//name, status="replace", action="write")
      write (unit, '(a)') text
      close (unit)
      call read_config("build/test-tmp/"//name, cfg, error)
      if (allocated(error)) return
      call run_parking(cfg, model, kinds, kind_of, error, max_batch=max_batch)
   end subroutine run_nml
end module test_helpers
