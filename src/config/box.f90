!> The `&box` group: the container (docs/namelist.md).
!>
!>     &box length = 20.0, 20.0, 20.0, periodic = .true. /
!>
!> Validates: all three edge lengths given, finite and > 0 mm.
!>
!> Usage:
!>     call load_box_config(box, nml, error)
!>     text = dump_box_config(box)
module anm_config_box
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_config_namelist, only: namelist_file_type, find_group, config_error, group_read_error, check_finite, &
      & max_line
   use anm_config_format, only: real_list, logical_text
   implicit none
   private

   public :: box_config_type, load_box_config, dump_box_config

   !> The box.
   type :: box_config_type
      !> Edge lengths, mm.
      real(wp) :: length(3) = 0.0_wp
      !> Periodic boundaries (otherwise hard walls).
      logical :: periodic = .true.
   end type box_config_type

contains

   !> Read and validate `&box` (required).
   subroutine load_box_config(self, nml, error)
      !> The box.
      type(box_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> Error naming file, line, group and variable.
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: unset = -huge(1.0_wp)
      real(wp) :: length(3)
      logical :: periodic
      namelist /box/ length, periodic
      integer :: ig, stat
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      length = unset
      periodic = self%periodic
      ig = find_group(nml, "box")
      if (ig == 0) then
         call fatal_error(error, nml%path//": namelist group &box is missing", error_code%format)
         return
      end if
      ! read from a local copy: gfortran 12 at -O3 corrupted the group's text when the namelist was
      ! read straight from the component of the intent(in) argument (every record does the same)
      lines = nml%groups(ig)%lines
      read (lines, nml=box, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call group_read_error(error, nml, ig, msg, reader)
         return
      end if
      if (any(length == unset)) then
         call config_error(error, nml, ig, "box", "length", "must give three edge lengths (mm)")
         return
      end if
      call check_finite(error, nml, ig, "box", "length", length)
      if (allocated(error)) return
      if (any(length <= 0.0_wp)) then
         call config_error(error, nml, ig, "box", "length", "= "//real_list(length)//": every edge must be > 0 mm")
         return
      end if
      self%length = length
      self%periodic = periodic

   contains

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=box, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_box_config

   !> The resolved `&box` group as namelist text (one line).
   pure function dump_box_config(self) result(text)
      !> The box.
      type(box_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      text = "&box length = "//real_list(self%length)//", periodic = "//logical_text(self%periodic)//" /"//new_line("a")
   end function dump_box_config
end module anm_config_box
