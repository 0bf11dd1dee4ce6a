!> The `&run` group: the base seed (docs/namelist.md).
!>
!>     &run seed = 42 /
!>
!> Validates: the seed is read as a 64-bit integer (any value; a value that does not fit is a
!> read error naming its line).
!>
!> Usage:
!>     call load_run_group_config(run, nml, error)
module anm_config_run
   use anm_core_kinds, only: i8
   use anm_core_error, only: error_type
   use anm_core_strings, only: to_string
   use anm_config_namelist, only: namelist_file_type, find_group, group_read_error, max_line
   implicit none
   private

   public :: run_group_config_type, load_run_group_config, dump_run_group_config

   !> The `&run` group.
   type :: run_group_config_type
      !> Base seed of every random stream (64-bit).
      integer(i8) :: seed = 1_i8
   end type run_group_config_type

contains

   !> Read `&run` (optional: defaults).
   subroutine load_run_group_config(self, nml, error)
      !> The `&run` group.
      type(run_group_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> Error naming file, line and group.
      type(error_type), allocatable, intent(out) :: error
      integer(i8) :: seed
      namelist /run/ seed
      integer :: ig, stat
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      seed = self%seed
      ig = find_group(nml, "run")
      if (ig == 0) return
      lines = nml%groups(ig)%lines
      read (lines, nml=run, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call group_read_error(error, nml, ig, msg, reader)
         return
      end if
      self%seed = seed

   contains

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=run, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_run_group_config

   !> The resolved `&run` group as namelist text.
   pure function dump_run_group_config(self) result(text)
      !> The `&run` group.
      type(run_group_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      text = "&run seed = "//to_string(self%seed)//" /"//new_line("a")
   end function dump_run_group_config
end module anm_config_run
