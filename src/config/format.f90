!> Small writers shared by the configuration dumps: values as namelist text.
!>
!> Usage:
!>     text = "length = "//real_list(box)//", periodic = "//logical_text(periodic)
module anm_config_format
   use anm_core_kinds, only: wp
   use anm_core_strings, only: to_string
   implicit none
   private

   public :: real_list, logical_text, quoted

   interface real_list
      module procedure :: real_list_1
   end interface real_list

contains

   !> Reals separated by ", ".
   pure function real_list_1(x) result(s)
      !> Values.
      real(wp), intent(in) :: x(:)
      character(len=:), allocatable :: s
      integer :: i
      s = ""
      do i = 1, size(x)
         if (i > 1) s = s//", "
         s = s//to_string(x(i))
      end do
   end function real_list_1

   !> ".true. " or ".false." as the resolved namelist has always written them.
   pure function logical_text(x) result(s)
      !> Value.
      logical, intent(in) :: x
      character(len=:), allocatable :: s
      s = merge(".true. ", ".false.", x)
   end function logical_text

   !> A string in single quotes, inner quotes doubled.
   pure function quoted(x) result(s)
      !> Value.
      character(len=*), intent(in) :: x
      character(len=:), allocatable :: s
      integer :: i
      s = "'"
      do i = 1, len(x)
         if (x(i:i) == "'") then
            s = s//"''"
         else
            s = s//x(i:i)
         end if
      end do
      s = s//"'"
   end function quoted
end module anm_config_format
